"""Run one program on the headless simulated LinuxCNC mill of sim/ and return its positions.

`simulate(program, acc_mm_s2)` copies sim/ into a fresh folder, sets the machine's
acceleration, starts `linuxcnc sim.ini` (its display, sim/display.py, runs the program and
exits, which shuts the machine down) and returns the commanded X, Y, Z (mm) of every servo
period. LinuxCNC's realtime part (rtapi_app) refuses to run as root, so as root the machine runs
as the unprivileged user SIM_USER (`useradd -m lcnc`; .ci/run creates it).

    python -m tests.linuxcnc.run_sim PROGRAM [ACC_MM_S2]   # prints the samples
"""

from __future__ import annotations

import fcntl
import json
import os
import pwd
import re
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

SIM = Path(__file__).resolve().parent / "sim"
SIM_USER = "lcnc"
SERVO_PERIOD_S = 0.001  # sim.ini [EMCMOT] SERVO_PERIOD
ACCELERATIONS_MM_S2 = (1000.0, 5000.0)
START_TIMEOUT_S = 900.0  # the whole run, start-up and shutdown included
# LinuxCNC runs one machine per computer: a second `linuxcnc` shuts the first one down
LOCK_FILE = Path(tempfile.gettempdir()) / "nurbsfeed-linuxcnc-sim.lock"
ACC_LINE = re.compile(r"^(MAX_(LINEAR_)?ACCELERATION\s*=\s*).*$", re.MULTILINE)


class SimulationError(RuntimeError):
    """LinuxCNC could not run the program to its end: the reason, as LinuxCNC gave it."""


def unavailable_reason() -> str | None:
    """Why the simulation cannot run here, or None when it can."""
    missing = [tool for tool in ("linuxcnc", "halsampler") if shutil.which(tool) is None]
    if missing:
        return (f"LinuxCNC not installed ({', '.join(missing)} not found; "
                "apt-get install linuxcnc-uspace)")
    if not Path("/usr/bin/python3").exists():
        return "/usr/bin/python3 not found (LinuxCNC's python module lives in its dist-packages)"
    if os.geteuid() == 0:
        try:
            pwd.getpwnam(SIM_USER)
        except KeyError:
            return (f"running as root, and LinuxCNC refuses to run as root: create the "
                    f"unprivileged user '{SIM_USER}' (useradd -m {SIM_USER})")
    return None


def simulate(program: Path, acc_mm_s2: float,
             traj: dict[str, str] | None = None) -> np.ndarray:
    """Commanded positions (N, 3) in mm, one per servo period, from start-up to shutdown.
    traj: INI [TRAJ] settings added to the machine's (e.g. ARC_BLEND_RAMP_FREQ)."""
    folder = Path(tempfile.mkdtemp(prefix="nurbsfeed-sim-"))
    try:
        shutil.copytree(SIM, folder, dirs_exist_ok=True)
        ini = folder / "sim.ini"
        text = ACC_LINE.sub(lambda m: f"{m.group(1)}{acc_mm_s2:g}", ini.read_text())
        added = "".join(f"{key} = {value}\n" for key, value in (traj or {}).items())
        ini.write_text(text.replace("[TRAJ]\n", f"[TRAJ]\n{added}", 1))
        shutil.copyfile(program, folder / "program.ngc")
        command = ["linuxcnc", str(ini)]
        if os.geteuid() == 0:
            user = pwd.getpwnam(SIM_USER)
            for path in [folder, *folder.rglob("*")]:
                os.chown(path, user.pw_uid, user.pw_gid)
            command = ["runuser", "-u", SIM_USER, "--", *command]
        environment = {key: value for key, value in os.environ.items()
                       if key not in ("DISPLAY", "PYTHONPATH", "VIRTUAL_ENV")}
        with open(LOCK_FILE, "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            done = _run_machine(command, folder, environment)
        result = folder / "result.json"
        if not result.exists():
            raise SimulationError(f"LinuxCNC did not run the program (exit {done.returncode}): "
                                  f"{(done.stdout + done.stderr).strip()[-2000:]}")
        errors = json.loads(result.read_text())["errors"]
        if errors:
            raise SimulationError("; ".join(errors))
        return read_samples((folder / "positions.txt").read_text())
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _run_machine(command: list[str], folder: Path,
                 environment: dict[str, str]) -> subprocess.CompletedProcess:
    """Run LinuxCNC in its own process group, so that a timeout or an interrupt stops all of
    it (the linuxcnc script shuts the machine down on SIGTERM)."""
    machine = subprocess.Popen(command, cwd=folder, env=environment, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
                               start_new_session=True)
    try:
        output, _ = machine.communicate(timeout=START_TIMEOUT_S)
    except subprocess.TimeoutExpired as timeout:
        os.killpg(machine.pid, signal.SIGTERM)
        machine.communicate()
        raise SimulationError(f"LinuxCNC did not finish in {START_TIMEOUT_S:g} s") from timeout
    except BaseException:
        os.killpg(machine.pid, signal.SIGTERM)
        machine.communicate()
        raise
    return subprocess.CompletedProcess(command, machine.returncode, output, "")


def read_samples(text: str) -> np.ndarray:
    """halsampler -t lines, `N x y z`: (N, 3). A gap in the sample numbers (the FIFO ran full
    and samples were lost) would shorten the measured time, so it is an error."""
    rows = [line.split() for line in text.splitlines() if line.strip()]
    if any(len(row) != 4 for row in rows):
        raise SimulationError("halsampler lost samples (overrun)")
    numbers = np.array([int(row[0]) for row in rows])
    if len(numbers) == 0 or np.any(np.diff(numbers) != 1):
        raise SimulationError("halsampler lost samples (a gap in the sample numbers)")
    return np.array([[float(value) for value in row[1:]] for row in rows])


if __name__ == "__main__":
    if reason := unavailable_reason():
        sys.exit(reason)
    acc = float(sys.argv[2]) if len(sys.argv) > 2 else ACCELERATIONS_MM_S2[0]
    np.savetxt(sys.stdout, simulate(Path(sys.argv[1]), acc), fmt="%.6f")
