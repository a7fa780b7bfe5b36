#!/usr/bin/python3
"""The simulated machine's display: run ./program.ngc once, record every servo period, exit.

LinuxCNC starts its DISPLAY program after the machine is up and shuts the machine down when it
exits. This one switches the machine on, homes it, runs the program in auto mode and waits
until the interpreter is idle, while halsampler copies the positions the HAL sampler records
each servo period into ./positions.txt. What happened goes into ./result.json for run_sim.py.
It runs under Debian's /usr/bin/python3, whose dist-packages hold LinuxCNC's `linuxcnc` module.
"""

import json
import subprocess
import sys
import time

import linuxcnc

PROGRAM_TIMEOUT_S = 600.0
POLL_S = 0.01
FIFO_DRAIN_TIMEOUT_S = 60.0


def wait_for(status, condition, what, timeout_s=30.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status.poll()
        if condition(status):
            return
        time.sleep(POLL_S)
    raise RuntimeError(f"timed out waiting for {what}")


def stop_sampling():
    """Stop recording and wait until halsampler has copied every recorded sample out of the
    FIFO: on a busy computer it can lag behind by seconds."""
    subprocess.run(["halcmd", "setp", "sampler.0.enable", "0"], check=True)
    deadline = time.monotonic() + FIFO_DRAIN_TIMEOUT_S
    while int(subprocess.run(["halcmd", "getp", "sampler.0.curr-depth"], check=True,
                             capture_output=True, text=True).stdout) > 0:
        if time.monotonic() > deadline:
            raise RuntimeError("halsampler did not empty the sampler's FIFO")
        time.sleep(POLL_S)


def run(errors):
    status, command, error_channel = linuxcnc.stat(), linuxcnc.command(), linuxcnc.error_channel()
    command.state(linuxcnc.STATE_ESTOP_RESET)
    command.state(linuxcnc.STATE_ON)
    wait_for(status, lambda s: s.task_state == linuxcnc.STATE_ON, "machine on")
    command.mode(linuxcnc.MODE_MANUAL)
    command.wait_complete()
    command.teleop_enable(0)
    command.wait_complete()
    command.home(-1)
    wait_for(status, lambda s: all(s.homed[:3]), "homing")
    command.mode(linuxcnc.MODE_AUTO)
    command.wait_complete()
    with open("positions.txt", "w") as positions:
        sampler = subprocess.Popen(["halsampler", "-t"], stdout=positions)
        try:
            command.program_open("program.ngc")
            command.wait_complete()
            command.auto(linuxcnc.AUTO_RUN, 0)
            wait_for(status, lambda s: s.interp_state != linuxcnc.INTERP_IDLE, "program start")
            deadline = time.monotonic() + PROGRAM_TIMEOUT_S
            while True:
                status.poll()
                message = error_channel.poll()
                if message:
                    errors.append(message[1])
                if (status.interp_state == linuxcnc.INTERP_IDLE and status.queue == 0
                        and status.inpos):
                    break
                if time.monotonic() > deadline:
                    errors.append("program did not finish")
                    break
                time.sleep(POLL_S)
            stop_sampling()
        finally:
            sampler.terminate()
            sampler.wait()
    message = error_channel.poll()
    if message:
        errors.append(message[1])


def main():
    errors = []
    try:
        run(errors)
    except Exception as failure:  # any failure is reported to run_sim.py, never a hang
        errors.append(f"{type(failure).__name__}: {failure}")
    with open("result.json", "w") as result:
        json.dump({"errors": errors}, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
