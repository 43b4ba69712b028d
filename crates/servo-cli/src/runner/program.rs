//! What a run applies over time: a closed-loop position reference, or a sequence of segments
//! (position references and open-loop voltages, e.g. from an experiment file).

use servo_core::control::sequence::{self, PlacedSegment, Segment, Setpoint, Target};
use servo_core::control::{RefSample, Reference};

/// The setpoint program of a run.
#[derive(Debug, Clone, PartialEq)]
pub enum Program {
    /// Closed loop on one reference for the whole run.
    Position(Reference),
    /// Segments one after the other (see [`servo_core::control::sequence`]).
    Segments(Vec<PlacedSegment>),
}

impl Program {
    /// Open loop: driver input u(t) [V] given by the generator `voltage` (its value read as V)
    /// for `duration_s`, 0 V after.
    pub fn open_loop(voltage: Reference, duration_s: f64) -> anyhow::Result<Program> {
        let p = PlacedSegment::after(&[], Segment::voltage(voltage, duration_s))
            .map_err(|e| anyhow::anyhow!("open-loop voltage program: {e}"))?;
        Ok(Program::Segments(vec![p]))
    }

    /// The setpoint at run time `t_s` [s].
    #[inline]
    pub fn at(&self, t_s: f64) -> Setpoint {
        match self {
            Program::Position(r) => Setpoint::Position(r.at(t_s)),
            Program::Segments(s) => sequence::setpoint_at(s, t_s),
        }
    }

    /// The program's own length [s] (`None` for a single reference, which lasts forever).
    pub fn duration_s(&self) -> Option<f64> {
        match self {
            Program::Position(_) => None,
            Program::Segments(s) => Some(sequence::duration_s(s)),
        }
    }

    /// True when some part runs closed loop (a controller is needed).
    pub fn needs_controller(&self) -> bool {
        match self {
            Program::Position(_) => true,
            Program::Segments(s) => s.iter().any(|p| p.segment.target == Target::Position),
        }
    }

    /// The reference sample at `t_s`, if closed loop there.
    pub fn position_at(&self, t_s: f64) -> Option<RefSample> {
        match self.at(t_s) {
            Setpoint::Position(r) => Some(r),
            Setpoint::Voltage { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
