"""Diagnose a directory of logs on a Dask cluster and collect the verdicts in one DataFrame.

    python fleet_dask.py LOG_DIR MODEL.toml [--workers N] [--pattern '*.mcap']
    python fleet_dask.py LOG_DIR MODEL.toml --trend CACHE_DIR [--workers N] [--pattern '*.mcap']

With ``--trend`` (:func:`fleet_trend`), each Dask task fits one log the way ``servo trend``
does and stores the fit in ``CACHE_DIR`` (a directory every worker sees: a shared file system
on a cluster); one final ``servo.trend`` on the whole directory then reads every fit from that
cache (0 fitted) and does the statistics: which actuator is wearing, how fast, and when it
reaches its limit.

One task per log: ``servo.diagnose`` releases the GIL, so thread workers run diagnoses side by
side. The same code runs on any Dask cluster (pass ``client=Client("tcp://scheduler:8786")``
to :func:`fleet_verdicts`); on Ray, ``ray.remote(one_verdict)`` plays the part of
``client.submit``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Dict, Optional

import pandas as pd

import servo


def one_verdict(log_path: str, model_toml: str, **options: Any) -> Dict[str, Any]:
    """One row: the log, the diagnosis status and winner, the verdict, or the error."""
    try:
        r = servo.diagnose(log_path, servo.Model.from_toml(model_toml), **options)
    except servo.Error as e:
        return {"log": log_path, "status": "error", "winner": None, "verdict": str(e)}
    best = (r.ranking or [{}])[0]
    return {
        "log": log_path,
        "status": r.status,
        "winner": r.winner,
        "best_candidate": best.get("effect"),
        "oe_reduction_pct": best.get("oe_reduction_pct"),
        "verdict": r.verdict,
    }


def fleet_verdicts(
    log_dir: str,
    model: servo.Model,
    pattern: str = "*.mcap",
    client: Optional[Any] = None,
    workers: int = 2,
    **options: Any,
) -> pd.DataFrame:
    """The verdicts of every log in ``log_dir`` matching ``pattern``, one row each."""
    from dask.distributed import Client, LocalCluster

    logs = sorted(str(p) for p in Path(log_dir).glob(pattern))
    own = client is None
    if own:
        cluster = LocalCluster(n_workers=1, threads_per_worker=workers, processes=False,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        futures = [client.submit(one_verdict, p, model.text, pure=False, **options) for p in logs]
        rows = client.gather(futures)
    finally:
        if own:
            client.close()
            cluster.close()
    return pd.DataFrame(rows, columns=["log", "status", "winner", "best_candidate",
                                       "oe_reduction_pct", "verdict"])


def fit_one(log_path: str, model_toml: str, cache_dir: str, **options: Any) -> Dict[str, Any]:
    """One log fitted into the shared cache: its cache counts, or the error."""
    try:
        r = servo.trend(log_path, servo.Model.from_toml(model_toml), cache=cache_dir, jobs=1,
                        **options)
    except servo.Error as e:
        return {"log": log_path, "hits": 0, "new": 0, "failed": 1, "error": str(e)}
    return {"log": log_path, **{k: r.cache[k] for k in ("hits", "new", "failed")}, "error": None}


def fleet_trend(
    log_dir: str,
    model: servo.Model,
    cache_dir: str,
    pattern: str = "*.mcap",
    client: Optional[Any] = None,
    workers: int = 2,
    **options: Any,
) -> servo.TrendResult:
    """``servo trend`` over ``log_dir`` with the per-log fits spread over a Dask cluster: one
    task per log fills ``cache_dir``, then one trend reads the fits back from it."""
    from dask.distributed import Client, LocalCluster

    logs = sorted(str(p) for p in Path(log_dir).rglob(pattern))
    own = client is None
    if own:
        cluster = LocalCluster(n_workers=1, threads_per_worker=workers, processes=False,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        futures = [client.submit(fit_one, p, model.text, cache_dir, pure=False, **options)
                   for p in logs]
        client.gather(futures)
    finally:
        if own:
            client.close()
            cluster.close()
    return servo.trend(log_dir, model, cache=cache_dir, **options)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log_dir")
    ap.add_argument("model")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--pattern", default="*.mcap")
    ap.add_argument("--trend", metavar="CACHE_DIR", help="servo trend with the fits on Dask")
    a = ap.parse_args()
    if a.trend:
        r = fleet_trend(a.log_dir, servo.Model.load(a.model), a.trend, a.pattern,
                        workers=a.workers)
        print(f"cache: {r.cache}")
        for c in r.changes:
            print(c["words"])
        return
    df = fleet_verdicts(a.log_dir, servo.Model.load(a.model), a.pattern, workers=a.workers)
    with pd.option_context("display.max_colwidth", 60, "display.width", 160):
        print(df.drop(columns=["verdict"]))


if __name__ == "__main__":
    main()
