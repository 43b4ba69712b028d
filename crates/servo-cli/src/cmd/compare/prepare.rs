//! `servo compare`: each log made ready for the replay: its controller (from the options, the
//! log, the gains file), the output limit, the check of the controller against the logged u, the
//! u rebuilt from the controller when the log has none, and the replay mode.

use super::*;

impl super::Compare {
    pub(super) fn mode_for(&self, log: &LogData) -> anyhow::Result<ModeChoice> {
        let seg = ((self.segment_s / log.measured.dt_s).round() as usize).max(1);
        let forced = self
            .mode
            .as_deref()
            .map(|s| parse_mode(s, self.k_steps.max(1), seg));
        let gains_source = log
            .controller
            .as_ref()
            .and_then(|g| g.part("gains"))
            .map(|p| p.source.as_str())
            .unwrap_or_default();
        let name = log.path.display();
        choose_mode(&log.replay(), forced, gains_source).map_err(|e| match e {
            ModeRefusal::NoController => anyhow!("--mode closed-loop needs the controller of {name}: give --gains gains.toml or --gains-from-log"),
            ModeRefusal::NoReferenceOrPosition => anyhow!(
                "--mode closed-loop needs the position reference and the measured position in {name} (map them with --columns ref=...,theta_l=...)"
            ),
            ModeRefusal::NoPosition => anyhow!(
                "--mode {} re-initialises from the measured position, which {name} does not have",
                self.mode.as_deref().unwrap_or_default()
            ),
            e => anyhow::Error::new(e),
        })
    }

    /// The output limit for a replay and where it came from: --u-limit-v, the log's metadata,
    /// the gains file's limit, or the plateau of the logged u.
    pub(super) fn u_limit(
        &self,
        m: &Measured,
        meta: &LogMeta,
        logged: Option<&LoggedController>,
        file: Option<(&GainsFile, &str)>,
    ) -> Option<(f64, String)> {
        if let Some(l) = self.u_limit_v {
            return Some((l, "given with --u-limit-v".into()));
        }
        let meta_limit = logged.and_then(|l| l.u_limit_v).or_else(|| {
            meta.get(meta_keys::U_LIMIT_V)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite() && *v > 0.0)
        });
        if let Some(l) = meta_limit {
            return Some((l, "from the log's metadata".into()));
        }
        if let Some((l, name)) = file.and_then(|(g, name)| g.pid.u_limit_v.map(|l| (l, name))) {
            return Some((l, format!("from {name}")));
        }
        detect_u_limit(&m.u_v).map(|l| (l, "the plateau of the logged u".into()))
    }

    /// The controller of one log: the gains of --gains or of the log's metadata, the options,
    /// the log's record and the gains file put together by [`pid_config`]; the output limit; the
    /// logged feedforward. Notes what an older log lacks.
    pub(super) fn log_controller(
        &self,
        log: &mut LogData,
        meta: &LogMeta,
        given: Option<&GainsFile>,
    ) -> anyhow::Result<()> {
        let logged = crate::io::logged_controller(meta)?;
        let log_gains = meta.gains()?;
        let given_name = self
            .gains
            .as_deref()
            .map(|p| p.display().to_string())
            .unwrap_or_default();
        let file = match (given, &log_gains) {
            (Some(g), _) => Some((g, given_name.as_str())),
            (None, Some(g)) => Some((g, "the gains in the log's metadata")),
            (None, None) => None,
        };
        let m = &log.measured;
        log.u_limit = self.u_limit(m, meta, logged.as_ref(), file);
        let name = log.path.display();
        match &logged {
            None if log_gains.is_some() => log.notes.push(format!(
                "{name} has no record of its controller's configuration (a log written before servo \
                 recorded it): discretisation from the [design] of the gains, derivative input, \
                 anti-windup and limit from the options, the gains file or the defaults; see the \
                 controller check"
            )),
            Some(l) if !l.missing().is_empty() => log.notes.push(format!(
                "{name}: the log's controller record lacks {}; those parts come from the options, \
                 the gains file or the defaults",
                l.missing().join(", ")
            )),
            _ => {}
        }
        // Feedforward: the run's selection, and the logged voltage if it has one.
        let ff_name = logged
            .as_ref()
            .and_then(|l| l.feedforward.clone())
            .or_else(|| meta.get(meta_keys::FEEDFORWARD).map(str::to_string));
        let ff_on = ff_name.as_deref().is_some_and(|n| n != "none");
        let ff_logged = meta
            .feedforward_v
            .as_ref()
            .filter(|f| f.len() == m.u_v.len() && f.iter().any(|v| v.is_finite() && *v != 0.0));
        log.feedforward = match (ff_logged, &ff_name) {
            (Some(_), n) => ControllerPart {
                part: "feedforward",
                value: n.clone().unwrap_or_else(|| "logged".into()),
                words: format!(
                    "feedforward {} added as logged (ff_v)",
                    n.as_deref().unwrap_or("of unknown terms")
                ),
                source: "from the log's samples".into(),
            },
            (None, Some(n)) if ff_on && meta.feedforward_v.is_none() => {
                log.notes.push(format!(
                    "{name}: the run added feedforward `{n}` but the log has no ff_v samples: the \
                     replay and the controller check run WITHOUT it and cannot reproduce the logged u"
                ));
                ControllerPart {
                    part: "feedforward",
                    value: format!("{n} (not replayed)"),
                    words: format!("feedforward {n} NOT replayed (no ff_v in the log)"),
                    source: "from the log's metadata".into(),
                }
            }
            (None, n) => ControllerPart {
                part: "feedforward",
                value: "none".into(),
                words: if ff_on {
                    format!(
                        "feedforward {} (zero throughout this log)",
                        n.as_deref().unwrap_or_default()
                    )
                } else {
                    "no feedforward".into()
                },
                source: if n.is_some() {
                    "from the log's metadata".into()
                } else {
                    "none known".into()
                },
            },
        };
        if ff_logged.is_some() {
            log.feedforward_v = meta.feedforward_v.clone();
        }
        if file.is_none() && logged.is_none() {
            return Ok(());
        }
        let src = PidSources {
            opts: &self.pid,
            logged: logged.as_ref(),
            gains_file: file,
        };
        // The period the loop ran at, as recorded (the log's time stamps give it to rounding).
        let ts_s = logged
            .as_ref()
            .and_then(|l| l.ts_s)
            .filter(|t| (t - m.dt_s).abs() <= 1e-6 * m.dt_s)
            .unwrap_or(m.dt_s);
        let mut r = pid_config(&src, ts_s, log.u_limit.clone())
            .with_context(|| format!("the controller of {name}"))?;
        r.parts.push(log.feedforward.clone());
        log.controller = Some(r);
        Ok(())
    }

    /// Checks the log's controller against the logged u; with --gains-from-log replaces it by the
    /// least-squares PID.
    pub(super) fn check_gains(&self, log: &mut LogData) -> anyhow::Result<()> {
        let m = &log.measured;
        let (Some(r), Some(th)) = (&m.ref_rad, &m.theta_l_rad) else {
            if self.gains_from_log {
                bail!(
                    "--gains-from-log needs the reference and the position in {}",
                    log.path.display()
                );
            }
            return Ok(());
        };
        let limit = log.u_limit.as_ref().map(|l| l.0);
        let ff = log.feedforward_v.as_deref();
        // Without a controller only the least-squares PID is wanted.
        let check = log
            .replay()
            .check_controller()
            .map_err(|e| anyhow!("controller: {e}"))?
            .ok_or_else(|| anyhow!("internal error: no reference or position to check"))?;
        if self.gains_from_log {
            let [kp, ki, kd] = check.ls_gains.ok_or_else(|| {
                anyhow!("--gains-from-log: the logged u of {} does not determine PID gains (singular least squares)", log.path.display())
            })?;
            if !(kp >= 0.0 && ki >= 0.0 && kd >= 0.0) {
                bail!(
                    "--gains-from-log: the least-squares PID of {} has a negative gain (kp = {kp:.4}, ki = {ki:.4}, kd = {kd:.4}); the logged u is not a PID on the logged error",
                    log.path.display()
                );
            }
            let fitted = GainsFile {
                pid: PidSection {
                    kp,
                    ki,
                    kd,
                    tl_s: 0.0,
                    ts_s: m.dt_s,
                    kw: None,
                    u_limit_v: None,
                    derivative_on: None,
                },
                design: None,
            };
            let label = format!(
                "the least-squares fit to the logged u (fit {:.1} %)",
                check.ls_fit_percent
            );
            let src = PidSources {
                opts: &self.pid,
                logged: None,
                gains_file: Some((&fitted, &label)),
            };
            let mut resolved = pid_config(&src, m.dt_s, log.u_limit.clone())?;
            resolved.parts.push(log.feedforward.clone());
            let mut c = ReplayController::new(&resolved.config, ff)
                .map_err(|e| anyhow!("controller: {e}"))?;
            let fitted_check = check_controller(&mut c, r, th, &m.u_v, ff, limit, m.dt_s);
            log.controller = Some(resolved);
            log.check = Some(fitted_check);
        } else if log.controller.is_some() {
            log.check = Some(check);
        }
        Ok(())
    }

    /// For a log without u: the u the controller commanded, rebuilt from the logged reference
    /// and position (the controller ran on exactly these), limited as the replay limits it. The
    /// closed-loop replay then runs from the reference; the u compared is this rebuilt one.
    pub(super) fn reconstruct_u(&self, log: &mut LogData) -> anyhow::Result<()> {
        let name = log.path.display().to_string();
        if self.gains_from_log {
            bail!("--gains-from-log: {name} has no u to fit the gains to; give --gains gains.toml");
        }
        if log.controller.is_none() {
            bail!(
                "{name} has no u (driver voltage): servo replays such a log in closed loop from the reference, which needs the controller that ran: give --gains gains.toml (the PID of `servo design` or the lab's gains)"
            );
        }
        let Some((limit, _)) = log.u_limit.clone() else {
            bail!(
                "{name} has no u, so the controller's output limit cannot be read off it: give --u-limit-v (e.g. 10 for a +/-10 V DAC) or `u_limit_v` in the gains file"
            );
        };
        let Some(u) = rebuild_u(&log.replay(), limit).map_err(|e| anyhow!("controller: {e}"))?
        else {
            return Ok(());
        };
        log.notes.push(format!(
            "{name} has no u: the closed loop is replayed from the reference with the controller (gains {}); the u shown is the controller's output on the logged position (rebuilt, not measured), limited to +/-{limit} V",
            log.controller
                .as_ref()
                .and_then(|g| g.part("gains"))
                .map(|p| p.source.as_str())
                .unwrap_or_default()
        ));
        if !self.json {
            if let Some(n) = log.notes.last() {
                eprintln!("note: {n}");
            }
        }
        log.record.u_v = Some(u.clone());
        log.measured.u_v = u;
        log.check = None;
        Ok(())
    }
}

pub(super) fn parse_mode(s: &str, k: usize, seg: usize) -> ReplayMode {
    match s {
        "closed-loop" => ReplayMode::ClosedLoop,
        "k-step" => ReplayMode::KStep { k },
        "segments" => ReplayMode::Segments { len: seg },
        _ => ReplayMode::Speed,
    }
}
