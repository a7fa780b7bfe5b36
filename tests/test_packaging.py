"""What `pip install .` ships: every package of the source tree (the Quick start installs that way,
not editable, so a package missing from pyproject's explicit list is missing for users)."""

from __future__ import annotations

from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_of_the_tree_is_listed_in_pyproject() -> None:
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setup["packages"])
    on_disk = {".".join(p.parent.relative_to(ROOT).parts)
               for p in (ROOT / "nurbsfeed").rglob("__init__.py")}
    assert on_disk - listed == set(), "packages pip install . would leave out"
    # the profiles ship as a package of their own, from the top-level configs/ folder
    assert setup["package-dir"]["nurbsfeed.configs"] == "configs"
    assert (ROOT / "configs" / "__init__.py").is_file()
    assert listed - on_disk == {"nurbsfeed.configs"}


def test_the_first_runs_warm_up_curve_ships_and_is_the_butterfly_sample() -> None:
    from nurbsfeed.commands.warm_up import WARM_UP_CURVE

    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert WARM_UP_CURVE.name in data["package-data"]["nurbsfeed.commands"]
    assert WARM_UP_CURVE.read_bytes() == (ROOT / "samples" / "butterfly.json").read_bytes()


def test_the_command_line_loads_without_numpy_or_numba_until_a_command_needs_them() -> None:
    # `nurbsfeed --help` / `--version` and click's option parsing must not pay for the
    # pipeline's imports (~0.3 s): they are taken inside the commands
    import subprocess
    import sys

    probe = ("import sys, nurbsfeed.cli; "
             "print(sorted(m for m in ('numpy', 'numba', 'scipy') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "[]"
