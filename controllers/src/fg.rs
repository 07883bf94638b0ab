//! Finger-gaiting (FG): `psi_FG = psi_IGM + psi_CS` on the same step.
//!
//! CS drives its switching finger along its trajectory ([`super::cs`]); IGM acts on the
//! fingertips in contact *other than* the switching finger (its J_S has zero columns for
//! that finger, so the two terms touch disjoint joints), for the whole trajectory, also
//! after the finger has touched down again. When CS cannot start (fewer than 4 contacts, or
//! no finger can leave) FG is IGM alone on all contacts; when IGM has no action mid-switch (fewer than 3 other
//! contacts, or a QP error) FG is CS alone. Only when neither acts is there no action.

use std::sync::Arc;

use vge_hand::Hand;

use super::cs::{CsConfig, CsController};
use super::igm::{IgmConfig, IgmController, fit_to_joint_limits, tip_contacts};
use super::{Controller, ControllerError, ControllerInput, limit_to_joint_range};

/// FG as a [`Controller`] (module docs).
#[derive(Debug, Clone)]
pub struct FgController {
    /// The in-grasp term.
    pub igm: IgmController,
    /// The switching term.
    pub cs: CsController,
}

impl FgController {
    /// FG on `hand` from the two controllers' configurations.
    #[must_use]
    pub fn new(hand: Arc<Hand>, igm: IgmConfig, cs: CsConfig) -> Self {
        Self { igm: IgmController::new(Arc::clone(&hand), igm), cs: CsController::new(hand, cs) }
    }
}

impl Controller for FgController {
    fn name(&self) -> &'static str {
        "fg"
    }

    fn reset(&mut self, rng: &mut dyn rand::Rng) {
        self.igm.reset(rng);
        self.cs.reset(rng);
    }

    fn act(&mut self, input: &ControllerInput, rng: &mut dyn rand::Rng) -> Result<Vec<f32>, ControllerError> {
        input.check_sizes(&self.igm.hand)?;
        let total = match self.cs.raw_step(input, rng) {
            Ok((finger, cs_delta)) => {
                let contacts = tip_contacts(input, Some(finger));
                let igm = super::igm::igm_step(
                    &self.igm.hand,
                    &input.q_rad,
                    &contacts,
                    input.object_position_m,
                    &self.igm.config,
                );
                match igm {
                    Ok(out) => {
                        let igm_delta =
                            fit_to_joint_limits(&self.igm.hand, &input.q_target_rad, &out, &self.igm.config);
                        igm_delta.iter().zip(&cs_delta).map(|(i, c)| i + c).collect()
                    }
                    Err(_) => cs_delta,
                }
            }
            // CS cannot start: IGM alone (its error, if any, is the informative one).
            Err(_) => self.igm.step_on(input, &tip_contacts(input, None))?,
        };
        Ok(limit_to_joint_range(&self.igm.hand, &input.q_target_rad, &total))
    }
}
