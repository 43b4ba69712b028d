//! What a run applies over time: a closed-loop position reference, a sequence of segments
//! (position references and open-loop voltages, e.g. from an experiment file), or a speed profile
//! (the identification experiments' staircase and ramps, run by the speed controller).

use super::reference::TIME_EPS_S;
use super::sequence::{self, PlacedSegment, Segment, SequenceError, Target};
use super::{RefSample, Reference};
use alloc::vec;
use alloc::vec::Vec;

/// Why a program could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ProgramError {
    /// The open-loop voltage segment is not valid.
    #[error("open-loop voltage program")]
    OpenLoop(#[source] SequenceError),
    /// A piece of a speed profile has a duration that is not a positive finite time.
    #[error("speed profile piece {index}: duration must be > 0 s, got {duration_s}")]
    PieceDuration { index: usize, duration_s: f64 },
    /// A piece of a speed profile has a non-finite speed or acceleration.
    #[error("speed profile piece {index}: non-finite speed {omega_l_rad_s} rad/s or acceleration {alpha_l_rad_s2} rad/s^2")]
    PieceNotFinite {
        index: usize,
        omega_l_rad_s: f64,
        alpha_l_rad_s2: f64,
    },
}

/// A generator of a program whose frequency the loop's sampling cannot carry
/// ([`Program::check_sampling`]).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{}{freq_hz} Hz is above the Nyquist frequency {nyquist_hz} Hz of the loop's sampling (the samples would alias it); lower the frequency, lengthen the PRBS bit or sample faster", segment.map_or(alloc::string::String::new(), |i| alloc::format!("segment {}: ", i + 1)))]
pub struct Aliased {
    /// The segment (0-based) of a sequence; `None` for a single reference.
    pub segment: Option<usize>,
    /// The generator's highest frequency [Hz] ([`Reference::highest_freq_hz`]).
    pub freq_hz: f64,
    /// 1 / (2 T_s) [Hz].
    pub nyquist_hz: f64,
}

/// The setpoint program of a run.
#[derive(Debug, Clone, PartialEq)]
pub enum Program {
    /// Closed loop on one reference for the whole run.
    Position(Reference),
    /// Segments one after the other (see [`super::sequence`]).
    Segments(Vec<PlacedSegment>),
    /// Closed loop on the load speed (the speed controller [`super::speed::SpeedLoop`] of the
    /// run loop).
    Speed(SpeedProfile),
}

/// What to apply at one instant of a [`Program`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Setpoint {
    /// Closed loop (PID) on this load-angle reference.
    Position(RefSample),
    /// Open loop: apply this driver input [V].
    Voltage { u_v: f64 },
    /// Closed loop (speed controller) on this load speed [rad/s] and acceleration [rad/s^2].
    /// Both zero is a rest: 0 V, the motor coasts.
    Speed {
        omega_l_rad_s: f64,
        alpha_l_rad_s2: f64,
    },
}

impl From<sequence::Setpoint> for Setpoint {
    fn from(s: sequence::Setpoint) -> Setpoint {
        match s {
            sequence::Setpoint::Position(r) => Setpoint::Position(r),
            sequence::Setpoint::Voltage { u_v } => Setpoint::Voltage { u_v },
        }
    }
}

impl Program {
    /// Open loop: driver input u(t) [V] given by the generator `voltage` (its value read as V)
    /// for `duration_s`, 0 V after.
    pub fn open_loop(voltage: Reference, duration_s: f64) -> Result<Program, ProgramError> {
        let p = PlacedSegment::after(&[], Segment::voltage(voltage, duration_s))
            .map_err(ProgramError::OpenLoop)?;
        Ok(Program::Segments(vec![p]))
    }

    /// Checks that a loop sampled every `ts_s` [s] reproduces the program's generators: none
    /// puts a frequency above the Nyquist frequency 1 / (2 ts_s) in its signal
    /// ([`Reference::highest_freq_hz`]), where the samples would alias it into another (a 1 GHz
    /// sine sampled at 1 kHz reads as a constant).
    pub fn check_sampling(&self, ts_s: f64) -> Result<(), Aliased> {
        let nyquist_hz = 0.5 / ts_s;
        let refs: Vec<(Option<usize>, &Reference)> = match self {
            Program::Position(r) => vec![(None, r)],
            Program::Segments(s) => s
                .iter()
                .enumerate()
                .map(|(i, p)| ((s.len() > 1).then_some(i), &p.segment.reference))
                .collect(),
            Program::Speed(_) => Vec::new(),
        };
        for (segment, r) in refs {
            if let Some(f) = r.highest_freq_hz() {
                // (A NaN frequency is refused too: the generators validate theirs.)
                if f.is_nan() || f > nyquist_hz * (1.0 + 1e-9) {
                    return Err(Aliased {
                        segment,
                        freq_hz: f,
                        nyquist_hz,
                    });
                }
            }
        }
        Ok(())
    }

    /// The setpoint at run time `t_s` [s].
    #[inline]
    pub fn at(&self, t_s: f64) -> Setpoint {
        match self {
            Program::Position(r) => Setpoint::Position(r.at(t_s)),
            Program::Segments(s) => sequence::setpoint_at(s, t_s).into(),
            Program::Speed(p) => {
                let (omega_l_rad_s, alpha_l_rad_s2) = p.at(t_s);
                Setpoint::Speed {
                    omega_l_rad_s,
                    alpha_l_rad_s2,
                }
            }
        }
    }

    /// The program's own length [s] (`None` for a single reference, which lasts forever).
    pub fn duration_s(&self) -> Option<f64> {
        match self {
            Program::Position(_) => None,
            Program::Segments(s) => Some(sequence::duration_s(s)),
            Program::Speed(p) => Some(p.duration_s()),
        }
    }

    /// True when some part runs closed loop on the position (a PID is needed).
    pub fn needs_controller(&self) -> bool {
        match self {
            Program::Position(_) => true,
            Program::Segments(s) => s.iter().any(|p| p.segment.target == Target::Position),
            Program::Speed(_) => false,
        }
    }

    /// True when some part runs closed loop on the speed (a speed controller is needed).
    pub fn needs_speed_loop(&self) -> bool {
        matches!(self, Program::Speed(_))
    }

    /// The reference sample at `t_s`, if closed loop on the position there.
    pub fn position_at(&self, t_s: f64) -> Option<RefSample> {
        match self.at(t_s) {
            Setpoint::Position(r) => Some(r),
            _ => None,
        }
    }
}

/// One piece of a [`SpeedProfile`]: the load speed starts at `omega_l_rad_s` and changes at the
/// constant rate `alpha_l_rad_s2` for `duration_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedPiece {
    /// Start time [s] from the beginning of the profile.
    pub start_s: f64,
    /// Length [s] (> 0).
    pub duration_s: f64,
    /// Load speed at the start [rad/s].
    pub omega_l_rad_s: f64,
    /// Load acceleration during the piece [rad/s^2].
    pub alpha_l_rad_s2: f64,
}

/// A piecewise-linear load-speed reference: holds (constant speed, zero acceleration) and ramps
/// (constant acceleration) one after the other. Before its start and after its end the
/// reference is a rest (speed and acceleration 0: 0 V, the motor coasts).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SpeedProfile {
    pieces: Vec<SpeedPiece>,
}

impl SpeedProfile {
    /// An empty profile.
    pub fn new() -> SpeedProfile {
        SpeedProfile::default()
    }

    /// Appends a hold at `omega_l_rad_s` [rad/s] for `duration_s` [s] (0 rad/s: a rest).
    pub fn hold(&mut self, duration_s: f64, omega_l_rad_s: f64) -> Result<(), ProgramError> {
        self.push(duration_s, omega_l_rad_s, 0.0)
    }

    /// Appends a ramp from `from_rad_s` to `to_rad_s` [rad/s] over `duration_s` [s].
    pub fn ramp(
        &mut self,
        duration_s: f64,
        from_rad_s: f64,
        to_rad_s: f64,
    ) -> Result<(), ProgramError> {
        self.push(duration_s, from_rad_s, (to_rad_s - from_rad_s) / duration_s)
    }

    fn push(&mut self, duration_s: f64, omega: f64, alpha: f64) -> Result<(), ProgramError> {
        let index = self.pieces.len();
        if !(duration_s.is_finite() && duration_s > 0.0) {
            return Err(ProgramError::PieceDuration { index, duration_s });
        }
        if !(omega.is_finite() && alpha.is_finite()) {
            return Err(ProgramError::PieceNotFinite {
                index,
                omega_l_rad_s: omega,
                alpha_l_rad_s2: alpha,
            });
        }
        self.pieces.push(SpeedPiece {
            start_s: self.duration_s(),
            duration_s,
            omega_l_rad_s: omega,
            alpha_l_rad_s2: alpha,
        });
        Ok(())
    }

    /// The pieces in order.
    pub fn pieces(&self) -> &[SpeedPiece] {
        &self.pieces
    }

    /// Length [s].
    pub fn duration_s(&self) -> f64 {
        self.pieces.last().map_or(0.0, |p| p.start_s + p.duration_s)
    }

    /// (load speed [rad/s], load acceleration [rad/s^2]) at `t_s` [s]. Times within 1 ns of a
    /// boundary count as at it, as in [`super::sequence`].
    pub fn at(&self, t_s: f64) -> (f64, f64) {
        if t_s < -TIME_EPS_S || t_s >= self.duration_s() - TIME_EPS_S {
            return (0.0, 0.0);
        }
        let i = self
            .pieces
            .partition_point(|p| p.start_s <= t_s + TIME_EPS_S)
            .saturating_sub(1);
        let p = &self.pieces[i];
        let dt = (t_s - p.start_s).max(0.0);
        (p.omega_l_rad_s + p.alpha_l_rad_s2 * dt, p.alpha_l_rad_s2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A generator above the loop's Nyquist frequency is refused, naming the segment of a
    /// sequence; at or below it (a PRBS of one-sample bits) it runs.
    #[test]
    fn generators_above_nyquist_are_refused() {
        let ts = 1e-3;
        let sine = |f: f64| Reference::parse(&alloc::format!("sine:amp=1,freq={f}")).unwrap();
        assert!(Program::Position(sine(100.0)).check_sampling(ts).is_ok());
        let e = Program::Position(sine(1e9)).check_sampling(ts).unwrap_err();
        assert_eq!((e.segment, e.nyquist_hz), (None, 500.0));
        let prbs = |bit: f64| {
            Program::open_loop(
                Reference::parse(&alloc::format!("prbs:amp=3,bit={bit}")).unwrap(),
                1.0,
            )
            .unwrap()
        };
        assert!(prbs(1e-3).check_sampling(ts).is_ok());
        assert!(prbs(5e-4).check_sampling(ts).is_err());
        let seq = |r: Reference| Segment::voltage(r, 1.0);
        let a = PlacedSegment::after(&[], seq(sine(10.0))).unwrap();
        let b = PlacedSegment::after(&[a], seq(sine(800.0))).unwrap();
        let e = Program::Segments(vec![a, b])
            .check_sampling(ts)
            .unwrap_err();
        assert_eq!(e.segment, Some(1));
        assert!(e.to_string().starts_with("segment 2: 800 Hz"), "{e}");
    }

    #[test]
    fn open_loop_and_reference() {
        let p = Program::open_loop(Reference::step(2.0, 0.0), 1.0).unwrap();
        assert_eq!(p.at(0.5), Setpoint::Voltage { u_v: 2.0 });
        assert_eq!(p.at(1.5), Setpoint::Voltage { u_v: 0.0 });
        assert!(!p.needs_controller());
        assert_eq!(p.duration_s(), Some(1.0));
        let p = Program::Position(Reference::parse("step:1.5").unwrap());
        assert_eq!(p.position_at(0.1).unwrap().pos_rad, 1.5);
        assert!(p.needs_controller());
    }

    #[test]
    fn speed_profile_holds_and_ramps() {
        let mut s = SpeedProfile::new();
        s.hold(0.5, 0.0).unwrap();
        s.ramp(1.0, 0.0, 10.0).unwrap();
        s.hold(2.0, -4.0).unwrap();
        assert_eq!(s.duration_s(), 3.5);
        assert_eq!(s.at(0.25), (0.0, 0.0));
        assert_eq!(s.at(1.0), (5.0, 10.0));
        assert_eq!(s.at(1.5), (-4.0, 0.0)); // a boundary belongs to the next piece
        assert_eq!(s.at(3.4), (-4.0, 0.0));
        assert_eq!(s.at(3.5), (0.0, 0.0)); // after the end: rest
        assert!(s.hold(0.0, 1.0).is_err() && s.ramp(1.0, f64::NAN, 0.0).is_err());
        let p = Program::Speed(s);
        assert!(p.needs_speed_loop() && !p.needs_controller());
        assert_eq!(p.duration_s(), Some(3.5));
        assert_eq!(
            p.at(1.0),
            Setpoint::Speed {
                omega_l_rad_s: 5.0,
                alpha_l_rad_s2: 10.0
            }
        );
    }
}
