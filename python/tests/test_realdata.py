"""to_dict() equals the CLI's --json on the real lab data (../shared/realdata or
$SERVO_REALDATA; skipped with a message when absent)."""

from __future__ import annotations

import servo

JACO_F = "time=t_s,omega_m=wm_deg_per_s:deg/s,i_a=ia_A,u=u_V"
JACO_I = "time=t_s,omega_l=wl_deg_per_s:deg/s,i_a=ia_A,u=u_V"


def test_identify_real_jacopisky(realdata, cli_json, tmp_path):
    d = realdata / "padova2021-jacopisky" / "csv"
    logs = [d / "friction_pos.csv", d / "friction_neg.csv", d / "accel_decel.csv"]
    r = servo.identify(logs, columns=[JACO_F, JACO_F, JACO_I])
    want = cli_json("identify", *logs, "--columns", JACO_F, "--columns", JACO_F, "--columns", JACO_I)
    assert r.to_dict() == want
    assert r.model is not None and r.model.params["tau_sf"] > 0


def test_compare_real_closed_loop_steps(realdata, cli_json, tmp_path):
    log = realdata / "padova2021-jacopisky" / "csv" / "pid_bode_steps.csv"
    cols = "time=t_s,theta_l=thl_meas_deg:deg,ref=thl_ref_deg:deg,u=u_V"
    model = servo.Model.lab()
    r = servo.compare(str(log), model, columns=cols)
    p = tmp_path / "lab.toml"
    p.write_text(model.text)
    assert r.to_dict()["schema"] == "servo.compare/1"
    want = cli_json("compare", log, "--columns", cols, "--model", p)
    got = r.to_dict()
    import json
    import re
    # the model is a temporary file for the package: its path is the only difference
    g = re.sub(r'"[^"]*servo-[^"/]+/model\.toml"', '"MODEL"', json.dumps(got))
    assert g == json.dumps(want).replace(json.dumps(str(p)), '"MODEL"')


def test_diagnose_real_logs_without_voltage(realdata, cli_json, tmp_path):
    d = realdata / "padova2022-mustacchi" / "csv"
    logs = [d / "friction_pos.csv", d / "friction_neg.csv", d / "inertia.csv"]
    model = tmp_path / "nominal.toml"
    model.write_text(servo.Model.table2().text)
    cols = "time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A"
    r = servo.diagnose([str(p) for p in logs], servo.Model.load(model), columns=cols)
    assert r.to_dict() == cli_json("diagnose", *logs, "--model", model, "--columns", cols)
    assert r.winner == "coulomb"
