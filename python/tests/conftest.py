"""Fixtures: the `servo` binary built in the same target directory as the package (the CLI
whose --json the results must equal), simulated logs made by that binary, the real lab data."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def servo_bin() -> Path:
    if os.environ.get("SERVO_BIN"):
        return Path(os.environ["SERVO_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "release" / "servo"


@pytest.fixture(scope="session")
def cli():
    """Runs the binary: cli(*args) -> (returncode, stdout, stderr)."""
    exe = servo_bin()
    if not exe.exists():
        pytest.fail(f"the servo binary is not built at {exe} (cargo build --release -p servo-cli)")

    def run(*args: str):
        p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True)
        return p.returncode, p.stdout, p.stderr

    return run


@pytest.fixture(scope="session")
def cli_json(cli):
    """The --json object of a successful command."""

    def run(*args: str):
        rc, out, err = cli(*args, "--json")
        assert rc == 0, err
        return json.loads(out)

    return run


@pytest.fixture(scope="session")
def story(tmp_path_factory, cli):
    """An open-loop log of the lab plant with a hidden imbalance (20 s of 0.5 Hz, 6 V sine),
    a closed-loop step log, their model identified by the CLI, and a controller."""
    d = tmp_path_factory.mktemp("story")
    rc, out, err = cli("params", "--preset", "lab")
    assert rc == 0, err
    (d / "lab.toml").write_text(out)
    plant = out + "\n[effects.imbalance]\namplitude = 0.01\n"
    (d / "plant.toml").write_text(plant)
    rc, _, err = cli("design", "--wc", "30", "--pm", "60", "-o", d / "gains.toml")
    assert rc == 0, err
    rc, _, err = cli("run", "--plant", d / "plant.toml", "--voltage", "sine:amp=6,freq=0.5",
                     "--duration", "20", "--seed", "3", "--log", d / "ol.mcap", "--progress", "never")
    assert rc == 0, err
    rc, _, err = cli("run", "--plant", d / "plant.toml", "--gains", d / "gains.toml", "--ref",
                     "square:amp=1,period=2", "--duration", "8", "--seed", "4", "--log",
                     d / "cl.mcap", "--progress", "never")
    assert rc == 0, err
    rc, _, err = cli("identify", d / "ol.mcap", "--method", "combined", "-o", d / "model.toml")
    assert rc == 0, err
    return d


def realdata_dir():
    """$SERVO_REALDATA, else ../shared/realdata beside the checkout; None (with a message)."""
    p = Path(os.environ.get("SERVO_REALDATA", REPO.parent / "shared" / "realdata"))
    return p if p.is_dir() else None


@pytest.fixture(scope="session")
def realdata():
    p = realdata_dir()
    if p is None:
        pytest.skip("real lab data not found (set SERVO_REALDATA or place shared/realdata beside the checkout)")
    return p
