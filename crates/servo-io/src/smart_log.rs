//! Smart-servo CSV logs (a goal position, the servo's angle, speed, PWM, supply and torque
//! enable, as a host polling a Dynamixel or Feetech servo writes them) read into a
//! [`servo_core::smart::SmartLog`].
//!
//! Columns are found by their header: time `t_s` (or `time_s`, `t`), goal `goal_rad`, angle
//! `theta_rad` (or `position_rad`, `present_position_rad`), speed `omega_rad_s` (optional), duty
//! `duty` (optional, the firmware's PWM as a signed fraction; never a commanded or derived
//! duty), supply `vin_meas_V` (or `v_supply_V`, `vin_V`; optional), torque enable
//! `torque_enable` (optional, 0 or 1). A supply column is a supply: it is never taken as the
//! motor's voltage.

use crate::error::Error;
use servo_core::smart::SmartLog;
use std::path::Path;

/// The most rows a smart-servo log may have (a day at 100 Hz is 8.6 million).
pub const MAX_ROWS: usize = 20_000_000;

const TIME: [&str; 3] = ["t_s", "time_s", "t"];
const GOAL: [&str; 2] = ["goal_rad", "goal_position_rad"];
const THETA: [&str; 3] = ["theta_rad", "position_rad", "present_position_rad"];
const OMEGA: [&str; 3] = ["omega_rad_s", "speed_rad_s", "velocity_rad_s"];
const DUTY: [&str; 2] = ["duty", "pwm"];
const SUPPLY: [&str; 4] = ["vin_meas_V", "v_supply_V", "vin_V", "input_voltage_V"];
const ENABLE: [&str; 1] = ["torque_enable"];

/// Reads a smart servo's log: a BAM JSON log (`.json`, [`crate::bam_log`]) or a smart-servo
/// CSV ([`read_smart_csv`]).
pub fn read_smart(path: &Path) -> Result<SmartLog, Error> {
    if crate::log_reader::extension(path) != "json" {
        return read_smart_csv(path);
    }
    let b = crate::bam_log::read_bam(path)?;
    let r = b.record;
    let log = SmartLog {
        name: r.source,
        goal_rad: r.ref_rad.unwrap_or_default(),
        theta_rad: r.theta_l_rad.unwrap_or_default(),
        omega_rad_s: r.omega_l_rad_s,
        duty: r.duty,
        v_supply_v: r.v_supply_v,
        torque_enable: r.enable.map(|e| e.iter().map(|x| *x != 0.0).collect()),
        time_s: r.time_s,
        kp_fw: b.kp_fw,
    };
    log.validate().map_err(|e| Error::Invalid(e.to_string()))?;
    Ok(log)
}

/// Reads a smart-servo CSV log (see the module for its columns).
pub fn read_smart_csv(path: &Path) -> Result<SmartLog, Error> {
    let name = path.display().to_string();
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| Error::Invalid(format!("{name}: {e}")))?;
    let header: Vec<String> = rd.headers()?.iter().map(str::to_string).collect();
    let find = |names: &[&str]| header.iter().position(|h| names.contains(&h.as_str()));
    let need = |names: &[&str], what: &str| {
        find(names).ok_or_else(|| {
            Error::Invalid(format!(
                "{name}: no {what} column (expected one of {}; the header has {})",
                names.join(", "),
                header.join(", ")
            ))
        })
    };
    let it = need(&TIME, "time")?;
    let ig = need(&GOAL, "goal position")?;
    let ith = need(&THETA, "angle")?;
    let (iw, id, iv, ie) = (find(&OMEGA), find(&DUTY), find(&SUPPLY), find(&ENABLE));
    let mut log = SmartLog {
        name: name.clone(),
        omega_rad_s: iw.map(|_| Vec::new()),
        duty: id.map(|_| Vec::new()),
        v_supply_v: iv.map(|_| Vec::new()),
        torque_enable: ie.map(|_| Vec::new()),
        ..SmartLog::default()
    };
    for (row, rec) in rd.records().enumerate() {
        let rec = rec?;
        let line = row + 2;
        if row >= MAX_ROWS {
            return Err(Error::Invalid(format!(
                "{name}: more than {MAX_ROWS} rows; cut the log into parts"
            )));
        }
        let num = |i: usize| -> Result<f64, Error> {
            let s = rec.get(i).unwrap_or("");
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "{name}, line {line}: column `{}` holds `{s}`, expected a finite number",
                        header[i]
                    ))
                })
        };
        log.time_s.push(num(it)?);
        log.goal_rad.push(num(ig)?);
        log.theta_rad.push(num(ith)?);
        if let (Some(i), Some(v)) = (iw, log.omega_rad_s.as_mut()) {
            v.push(num(i)?);
        }
        if let (Some(i), Some(v)) = (id, log.duty.as_mut()) {
            v.push(num(i)?);
        }
        if let (Some(i), Some(v)) = (iv, log.v_supply_v.as_mut()) {
            v.push(num(i)?);
        }
        if let (Some(i), Some(v)) = (ie, log.torque_enable.as_mut()) {
            let x = num(i)?;
            if x != 0.0 && x != 1.0 {
                return Err(Error::Invalid(format!(
                    "{name}, line {line}: torque_enable holds {x}, expected 0 or 1"
                )));
            }
            v.push(x == 1.0);
        }
    }
    log.validate().map_err(|e| Error::Invalid(e.to_string()))?;
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_columns_and_refuses_a_bad_enable() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.csv");
        std::fs::write(
            &p,
            "t_s,theta_rad,goal_rad,duty,vin_meas_V,torque_enable\n0,0,0.1,0.2,7.4,1\n0.01,0.01,0.1,0.1,7.3,1\n0.02,0.02,0.1,0,7.3,0\n",
        )
        .unwrap();
        let l = read_smart_csv(&p).unwrap();
        assert_eq!(l.time_s.len(), 3);
        assert_eq!(l.torque_enable, Some(vec![true, true, false]));
        assert_eq!(l.v_supply_v, Some(vec![7.4, 7.3, 7.3]));
        assert!(l.omega_rad_s.is_none());
        std::fs::write(&p, "t_s,theta_rad,goal_rad,torque_enable\n0,0,0,2\n").unwrap();
        let e = read_smart_csv(&p).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("torque_enable"), "{e}");
        std::fs::write(&p, "t_s,theta_rad,vin_meas_V\n0,0,7\n").unwrap();
        let e = read_smart_csv(&p).unwrap_err().to_string();
        assert!(e.contains("goal"), "{e}");
    }
}
