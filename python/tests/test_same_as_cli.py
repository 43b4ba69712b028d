"""Every result's .to_dict() is the CLI's --json for the same inputs (simulated logs)."""

from __future__ import annotations

import servo


def test_version_is_the_cli_version(cli):
    rc, out, _ = cli("--version")
    assert rc == 0
    assert out.split()[-1] == servo.__version__


def test_design_equals_cli(cli_json):
    cases = [
        (dict(wc_rad_s=30, pm_deg=60), ["--wc", "30", "--pm", "60"]),
        (dict(wc_rad_s=10, pm_deg=60, controller="pi", ts_s=0.002),
         ["--wc", "10", "--pm", "60", "--controller", "pi", "--ts", "0.002"]),
        (dict(overshoot=0.1, settling_time_s=0.15, alpha=6, exact=True),
         ["--overshoot", "0.1", "--settling-time", "0.15", "--alpha", "6", "--exact"]),
    ]
    for kw, flags in cases:
        r = servo.design(**kw)
        assert r.to_dict() == cli_json("design", *flags), kw
        assert r.gains is not None and r.gains.pid["kp"] == r.kp


def test_design_on_a_model_file(story, cli_json):
    r = servo.design(30, 60, params=servo.Model.load(story / "model.toml"))
    assert r.to_dict() == cli_json("design", "--wc", "30", "--pm", "60", "--params", story / "model.toml")
    assert r.to_dict() != servo.design(30, 60).to_dict()


def test_identify_equals_cli(story, cli_json):
    log = str(story / "ol.mcap")
    r = servo.identify(log, method="combined")
    assert r.to_dict() == cli_json("identify", log, "--method", "combined")
    assert r.model is not None
    assert r.model.params["j_eq"] == r.to_dict()["j_eq_kg_m2"]["value"]
    # the same through read_log's DataFrame and a Log
    assert servo.identify(servo.read_log(log), method="combined").to_dict() == r.to_dict()
    assert servo.identify([servo.Log.read(log)], method="combined").to_dict() == r.to_dict()


def test_compare_equals_cli_open_and_closed_loop(story, cli_json):
    model = servo.Model.load(story / "model.toml")
    for log, extra in [(story / "ol.mcap", []), (story / "cl.mcap", ["--gains", story / "gains.toml"])]:
        gains = servo.Gains.load(story / "gains.toml") if extra else None
        r = servo.compare(str(log), model, gains)
        assert r.to_dict() == cli_json("compare", log, "--model", story / "model.toml", *extra)
    # both logs in one call, and an option
    r = servo.compare([story / "ol.mcap", story / "cl.mcap"], model, mode="k-step", k_steps=20)
    assert r.to_dict() == cli_json("compare", story / "ol.mcap", story / "cl.mcap", "--model",
                                   story / "model.toml", "--mode", "k-step", "--k-steps", "20")


def _save_path_apart(d):
    """The JSON with the `save` object's path taken out: the package writes the model it returns
    to a file of its own, the CLI to the user's --save path; everything else must be equal."""
    d = dict(d)
    if isinstance(d.get("save"), dict):
        d["save"] = {k: v for k, v in d["save"].items() if k != "path"}
    return d


def test_add_equals_cli_and_the_error_falls(story, cli_json, tmp_path):
    model = servo.Model.load(story / "model.toml")
    r = model.add("imbalance", story / "ol.mcap")
    want = cli_json("compare", story / "ol.mcap", "--model", story / "model.toml", "--add",
                    "imbalance", "--save", tmp_path / "m2.toml")
    assert _save_path_apart(r.to_dict()) == _save_path_apart(want)
    assert r.model is not None and "imbalance" in r.model.effects
    assert r.model.text == (tmp_path / "m2.toml").read_text()
    before = servo.compare(story / "ol.mcap", model).fit_pct
    after = servo.compare(story / "ol.mcap", r.model).fit_pct
    assert before is not None and after is not None and after > before + 1.0, (before, after)


def test_diagnose_equals_cli(story, cli_json, tmp_path):
    r = servo.diagnose(story / "ol.mcap", servo.Model.load(story / "model.toml"), auto=True)
    want = cli_json("diagnose", story / "ol.mcap", "--model", story / "model.toml", "--auto",
                    "--save", tmp_path / "d.toml")
    assert _save_path_apart(r.to_dict()) == _save_path_apart(want)
    assert r.winner == "imbalance" and r.added == ["imbalance"] and r.status == "complete"
    assert r.model is not None and r.model.text == (tmp_path / "d.toml").read_text()
    costs = [rung["oe_cost_rad"] for rung in r.ladder]
    assert costs[-1] < 0.5 * costs[0], costs


def test_in_memory_logs_equal_their_csv(story, cli_json, tmp_path):
    """A Log built from arrays is what the CLI reads from the same samples as servo's CSV."""
    src = servo.Log.read(story / "ol.mcap")
    log = servo.Log.from_arrays(**{k: v for k, v in src.signals.items()})
    assert log.path is None
    r = servo.compare(log, story / "model.toml")
    rc_csv = tmp_path / "ol.csv"
    import subprocess
    from conftest import servo_bin
    subprocess.run([str(servo_bin()), "export", str(story / "ol.mcap"), "-o", str(rc_csv)], check=True,
                   capture_output=True)
    want = cli_json("compare", rc_csv, "--model", story / "model.toml")
    import json
    import re
    # the log's name differs (a temporary file); everything else is the same
    got = re.sub(r'"[^"]*servo-[^"/]+/log0\.csv"', '"LOG"', json.dumps(r.to_dict()))
    assert got == json.dumps(want).replace(json.dumps(str(rc_csv)), '"LOG"')


def test_trend_equals_cli_and_reuses_its_cache(story, cli_json, tmp_path):
    """servo.trend is `servo trend --json`: the same document, and a second call on the same
    cache fits nothing again."""
    import shutil
    fleet = tmp_path / "fleet"
    for unit in ("u1", "u2"):
        (fleet / unit).mkdir(parents=True)
        shutil.copy(story / "ol.mcap", fleet / unit / "ol.mcap")
        shutil.copy(story / "cl.mcap", fleet / unit / "cl.mcap")
    cache = tmp_path / "cache"
    r = servo.trend(fleet, servo.Model.load(story / "model.toml"), cache=str(cache), jobs=1,
                    limits={"tau_sf": 0.05})
    d = r.to_dict()
    assert d["schema"] == "servo.trend/1"
    assert [a["actuator"] for a in d["actuators"]] == ["u1", "u2"], d["actuators"]
    # the cache is keyed by content: u2's logs are copies of u1's, fitted once
    assert d["cache"]["new"] == 2 and d["cache"]["hits"] == 2, d["cache"]
    want = cli_json("trend", fleet, "--model", story / "model.toml", "--cache", cache, "--jobs",
                    "1", "--limit", "tau_sf=0.05", "--quiet")
    assert want["cache"]["hits"] == 4 and want["cache"]["new"] == 0, want["cache"]
    assert [a["parameters"] for a in d["actuators"]] == [a["parameters"] for a in want["actuators"]]
    again = servo.trend(fleet, story / "model.toml", cache=str(cache), jobs=1,
                        limits={"tau_sf": 0.05})
    assert again.cache["hits"] == 4 and again.cache["new"] == 0, again.cache


def test_a_current_drive_run_keeps_its_command(cli_json, tmp_path):
    """servo.simulate on a plant with a current [drive] and an open-loop ``command``: the log
    holds the drive's reference ``i_ref_a`` [A] and no ``u_v``; identify on it equals the CLI's,
    and the same samples as arrays (written as servo's CSV, ``i_ref_A``) identify the same."""
    plant = tmp_path / "drive.toml"
    plant.write_text(
        "[params]\nk_t = 0.045\nj_m = 2.0e-5\nn = 8.0\nj_eq = 6.0e-5\nb_eq = 1.0e-5\n"
        "tau_sf = 0.1\n\n[drive]\nkind = \"current\"\nbandwidth_hz = 300\ni_limit_a = 5.0\n"
    )
    log = servo.simulate(plant=plant, command="prbs:amp=1,bit=0.3", duration_s=6.0, seed=3)
    sig = log.signals
    assert "i_ref_a" in sig and "u_v" not in sig, list(sig)
    assert abs(abs(sig["i_ref_a"]).max() - 1.0) < 1e-12
    r = servo.identify(log, params=plant)
    assert r.to_dict() == cli_json("identify", log.path, "--params", plant)
    j = r.to_dict()["j_eq_kg_m2"]["value"]
    assert abs(j / 6.0e-5 - 1.0) < 0.03, j
    mem = servo.Log.from_arrays(**sig)
    assert servo.identify(mem, params=plant).to_dict()["j_eq_kg_m2"] == r.to_dict()["j_eq_kg_m2"]
