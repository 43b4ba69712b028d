"""Writes servo's CSV log (time_s,u_V,theta_l_rad,i_a_A,...,omega_l_rad_s) as a ROS 2 bag (rosbags,
MCAP storage) and a WPILib DataLog (robotpy-wpiutil), for tests/e2e/robotics_logs.rs.

usage: write_logs.py run.csv BAG_DIR OUT.wpilog
       write_logs.py --sysid OUT.wpilog MOTOR.csv...   (a SysIdRoutine-style log of four tests)
The bag: /joint_states (sensor_msgs/msg/JointState, joint `arm`, header stamps, at the log's
rate, logged 3 ms after their stamps), /cmd_voltage and /current (std_msgs/msg/Float64). The DataLog: voltage-arm [V], position-arm [rot],
velocity-arm [rot/s], current-arm [A], timestamps in microseconds.
"""
import csv
import math
import sys


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in rows[0]}


def write_bag(cols, out):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    JointState = ts.types["sensor_msgs/msg/JointState"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    Float64 = ts.types["std_msgs/msg/Float64"]
    import numpy as np

    t0_ns = 1_700_000_000 * 10**9
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        js = w.add_connection("/joint_states", JointState.__msgtype__, typestore=ts)
        cmd = w.add_connection("/cmd_voltage", Float64.__msgtype__, typestore=ts)
        cur = w.add_connection("/current", Float64.__msgtype__, typestore=ts)
        for k, t in enumerate(cols["time_s"]):
            ns = t0_ns + round(t * 1e9)
            # the log time lags the stamp by 3 ms: the reader must use the stamp
            log_ns = ns + 3_000_000
            msg = JointState(
                header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                name=["arm"],
                position=np.array([cols["theta_l_rad"][k]]),
                velocity=np.array([cols["omega_l_rad_s"][k]]),
                effort=np.array([], dtype=np.float64),
            )
            w.write(js, log_ns, ts.serialize_cdr(msg, JointState.__msgtype__))
            w.write(cmd, ns, ts.serialize_cdr(Float64(data=cols["u_V"][k]), Float64.__msgtype__))
            if "i_a_A" in cols:
                w.write(cur, ns, ts.serialize_cdr(Float64(data=cols["i_a_A"][k]), Float64.__msgtype__))


def write_wpilog(cols, out, motor="arm"):
    import wpiutil
    from wpiutil.log import DoubleLogEntry

    w = wpiutil.DataLogWriter(out, "servo e2e")
    t0_us = 5_000_000
    v = DoubleLogEntry(w, f"voltage-{motor}", "Volt", t0_us)
    p = DoubleLogEntry(w, f"position-{motor}", "Rotation", t0_us)
    s = DoubleLogEntry(w, f"velocity-{motor}", "Rotation per Second", t0_us)
    c = DoubleLogEntry(w, f"current-{motor}", "Amp", t0_us)
    for k, t in enumerate(cols["time_s"]):
        us = t0_us + round(t * 1e6)
        v.append(cols["u_V"][k], us)
        p.append(cols["theta_l_rad"][k] / (2 * math.pi), us)
        s.append(cols["omega_l_rad_s"][k] / (2 * math.pi), us)
        if "i_a_A" in cols:
            c.append(cols["i_a_A"][k], us)
        if k % 1000 == 999:
            w.flush()  # DataLogWriter's buffers are bounded: append waits for a flush
    w.flush()
    w.stop()


def write_sysid(out, tests):
    """tests: (state, csv) pairs, written one after the other with a 1 s gap, as SysIdRoutine
    logs them (samples only while a test runs, the state `none` between)."""
    import wpiutil
    from wpiutil.log import DoubleLogEntry, StringLogEntry

    w = wpiutil.DataLogWriter(out)
    v = DoubleLogEntry(w, "voltage-arm", "Volt")
    p = DoubleLogEntry(w, "position-arm", "Rotation")
    s = DoubleLogEntry(w, "velocity-arm", "Rotation per Second")
    state = StringLogEntry(w, "sysid-test-state-arm")
    start_us = 1_000_000
    for name, path in tests:
        cols = read_csv(path)
        for k, t in enumerate(cols["time_s"]):
            us = start_us + round(t * 1e6)
            state.append(name, us)
            v.append(cols["u_V"][k], us)
            p.append(cols["theta_l_rad"][k] / (2 * math.pi), us)
            s.append(cols["omega_l_rad_s"][k] / (2 * math.pi), us)
            if k % 1000 == 999:
                w.flush()
        end = start_us + round(cols["time_s"][-1] * 1e6)
        state.append("none", end + 1000)
        start_us = end + 1_000_000
    w.flush()
    w.stop()


if __name__ == "__main__":
    if sys.argv[1] == "--sysid":
        names = ["quasistatic-forward", "quasistatic-reverse", "dynamic-forward", "dynamic-reverse"]
        write_sysid(sys.argv[2], list(zip(names, sys.argv[3:])))
    else:
        cols = read_csv(sys.argv[1])
        write_bag(cols, sys.argv[2])
        write_wpilog(cols, sys.argv[3])
