//! Finger gaiting, read off fingertip contacts: a *contact switch* is a fingertip that
//! touched the object, let go for at least [`MIN_DETACH_STEPS`] control steps, and touched
//! it again. Counted per episode by evaluation (the evidence that a policy gaits) and per
//! 1k env steps by training (whether the behaviour policy completes the controller's
//! switches). In vge-sim, beside the contacts it reads, so that evaluation, the controller
//! rollouts and the bridge count switches the same way.

/// Shortest break that counts: 3 control steps (0.15 s at 20 Hz). A one- or two-step
/// flicker of a sliding tip is contact noise, not a switch; CS's detach phase alone takes
/// 20 steps at H = 50.
pub const MIN_DETACH_STEPS: u32 = 3;

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
enum Finger {
    /// Has not touched the object yet this episode.
    #[default]
    NeverTouched,
    Touching,
    /// Let go this many steps ago.
    Detached(u32),
}

/// Per-episode contact-switch counter.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ContactSwitches {
    /// One per fingertip, in the hand's finger order.
    fingers: Vec<Finger>,
    /// Switches completed so far.
    pub count: u32,
}

impl ContactSwitches {
    /// A counter for an episode whose first contacts are `touching`.
    #[must_use]
    pub fn new(touching: &[bool]) -> Self {
        let fingers =
            touching.iter().map(|&t| if t { Finger::Touching } else { Finger::NeverTouched }).collect();
        Self { fingers, count: 0 }
    }

    /// Feeds one step's fingertip contacts (as many as at the start); returns the switches
    /// completed on this step.
    pub fn update(&mut self, touching: &[bool]) -> u32 {
        let mut completed = 0;
        for (state, &t) in self.fingers.iter_mut().zip(touching) {
            *state = match (*state, t) {
                (Finger::Detached(n), true) => {
                    if n >= MIN_DETACH_STEPS {
                        completed += 1;
                    }
                    Finger::Touching
                }
                (Finger::Detached(n), false) => Finger::Detached(n.saturating_add(1)),
                (Finger::Touching, false) => Finger::Detached(1),
                (_, true) => Finger::Touching,
                (Finger::NeverTouched, false) => Finger::NeverTouched,
            };
        }
        self.count += completed;
        completed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Five fingertips (the count is the caller's), all touching but `f`, which is `t`.
    fn only(f: usize, t: bool) -> Vec<bool> {
        let mut c = vec![true; 5];
        c[f] = t;
        c
    }

    #[test]
    fn a_break_and_remake_counts_once_and_a_flicker_does_not() {
        let mut s = ContactSwitches::new(&[true; 5]);
        // Finger 2 lets go for 2 steps (a flicker), then for 5 (a switch).
        for t in [false, false, true, false, false, false, false, false, true, true] {
            s.update(&only(2, t));
        }
        assert_eq!(s.count, 1);
    }

    #[test]
    fn a_finger_that_never_touched_makes_no_switch_when_it_first_touches() {
        let mut s = ContactSwitches::new(&only(4, false));
        for _ in 0..10 {
            s.update(&only(4, false));
        }
        assert_eq!(s.update(&only(4, true)), 0);
        assert_eq!(s.count, 0);
    }
}
