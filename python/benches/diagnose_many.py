"""Benchmark: servo.diagnose_many on N one-minute logs with W workers, against N sequential
`servo diagnose LOG --model M --json` calls of the CLI binary (same logs, same model).

    python python/benches/diagnose_many.py [--logs 20] [--workers 2] [--duration 60]

Prints both wall times and the time per log; checks that every result equals the CLI's JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import servo

REPO = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--servo", default=str(Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target")) / "release" / "servo"))
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="servo-bench-") as tmp:
        d = Path(tmp)
        plant = servo.Plant.lab().with_effect("imbalance", amplitude=0.01)
        logs = []
        for i in range(a.logs):
            p = d / f"log{i:02}.mcap"
            lg = servo.simulate(plant, voltage="sine:amp=6,freq=0.5", duration_s=a.duration, seed=100 + i)
            os.replace(lg.path, p)
            logs.append(str(p))
        model = servo.identify(logs[0], method="combined").model
        model.save(d / "model.toml")
        t0 = time.perf_counter()
        cli = []
        for p in logs:
            out = subprocess.run([a.servo, "diagnose", p, "--model", str(d / "model.toml"), "--json"],
                                 capture_output=True, text=True, check=True).stdout
            cli.append(json.loads(out))
        t_cli = time.perf_counter() - t0
        t0 = time.perf_counter()
        got = servo.diagnose_many(logs, servo.Model.load(d / "model.toml"), workers=a.workers)
        t_py = time.perf_counter() - t0
        same = all(r.to_dict() == c for r, c in zip(got, cli))
        winners = sorted({r.winner or "-" for r in got})
        print(f"{a.logs} logs of {a.duration:.0f} s, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print(f"CLI, sequential:             {t_cli:7.1f} s  ({t_cli / a.logs:.2f} s per log)")
        print(f"diagnose_many, {a.workers} workers:   {t_py:7.1f} s  ({t_py / a.logs:.2f} s per log)")
        print(f"results equal to the CLI's JSON: {same}; winners: {', '.join(winners)}")
        if not same:
            sys.exit(1)


if __name__ == "__main__":
    main()
