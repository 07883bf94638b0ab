//! The metrics window: sums over the env steps since the last `metrics.csv` row, and the
//! row they become.

use serde::{Deserialize, Serialize};
use vge_sim::{EpisodeOutcome, ObjectShape};

use crate::behaviour::BehaviourStats;
use crate::learner::UpdateStats;

pub(super) const METRICS_HEADER: &str = "step,episodes,return,rotation,contacts,success,controller_share,p_psi,switches_per_1k,critic_loss,actor_loss,bc_loss,alpha,mean_q,mc_return,mc_return_max,mc_return_early,actor_log_std,beta,updates,steps_per_s";

/// Sums over the current metrics window.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub(super) struct Window {
    episodes: u64,
    ret: f64,
    rotation: f64,
    contacts: f64,
    successes: u64,
    updates: u64,
    critic_loss: f64,
    actor_loss: f64,
    bc_loss: f64,
    alpha: f64,
    mean_q: f64,
    steps: u64,
    controller_steps: u64,
    selections: u64,
    p_psi_sum: f64,
    /// Fingertip contact switches completed ([`vge_sim::gait`]).
    pub switches: u64,
    /// Discounted Monte-Carlo returns of the visited states of the finished episodes (sum,
    /// count, largest): what the critic's mean Q should stay within.
    mc_return_sum: f64,
    mc_return_count: u64,
    mc_return_max: Option<f64>,
    /// The same returns of the episodes' early steps only ([`Discount::early_steps`]), whose
    /// return the time limit cuts by little: a reading of the critic's gap without the
    /// truncation's bias.
    mc_return_early_sum: f64,
    mc_return_early_count: u64,
    /// Per training object of a run on several ([`TrainingObjects`]); empty, and left out of
    /// the checkpoint, on one object.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    per_object: Vec<ObjectWindow>,
}

/// The finished episodes of one training object in the window.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
struct ObjectWindow {
    episodes: u64,
    ret: f64,
    rotation: f64,
    successes: u64,
}

/// The distinct objects of a run (`env.objects`, first appearance first), and which of them
/// each env holds: env `i` holds `objects[i % objects.len()]`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct TrainingObjects {
    distinct: Vec<ObjectShape>,
    of_env: Vec<usize>,
}

impl TrainingObjects {
    pub fn new(objects: &[ObjectShape], num_envs: usize) -> Self {
        let mut distinct: Vec<ObjectShape> = Vec::new();
        for &o in objects {
            if !distinct.contains(&o) {
                distinct.push(o);
            }
        }
        let of_env = (0..num_envs)
            .map(|i| {
                let shape = objects.get(i % objects.len().max(1)).copied();
                shape.and_then(|s| distinct.iter().position(|&d| d == s)).unwrap_or(0)
            })
            .collect();
        Self { distinct, of_env }
    }

    /// More than one object: the metrics gain per-object columns.
    pub fn several(&self) -> bool {
        self.distinct.len() > 1
    }

    /// The per-object columns of `metrics.csv` (none on one object): each object's success,
    /// return and rotation per finished episode, `<object>_success` and so on.
    pub fn columns(&self) -> Vec<String> {
        if !self.several() {
            return Vec::new();
        }
        self.distinct
            .iter()
            .flat_map(|o| OBJECT_FIGURES.map(|figure| format!("{}_{figure}", o.name())))
            .collect()
    }

    /// `metrics.csv`'s header for this run.
    pub fn metrics_header(&self) -> String {
        std::iter::once(METRICS_HEADER.to_owned()).chain(self.columns()).collect::<Vec<_>>().join(",")
    }
}

/// The figures of each object in a multi-object run's metrics, in column order.
const OBJECT_FIGURES: [&str; 3] = ["success", "return", "rotation"];

impl Window {
    /// A finished episode, with its rewards for the Monte-Carlo returns.
    pub fn add_episode(&mut self, outcome: &EpisodeOutcome, rewards: &[f32], discount: Discount) {
        self.episodes += 1;
        self.ret += outcome.episode_return;
        self.rotation += outcome.rotation_rad;
        self.contacts += outcome.mean_contacts;
        self.successes += u64::from(outcome.success());
        let returns = discounted_returns(rewards, discount);
        self.mc_return_sum += returns.sum;
        self.mc_return_count += returns.count;
        self.mc_return_early_sum += returns.early_sum;
        self.mc_return_early_count += returns.early_count;
        self.mc_return_max = match (self.mc_return_max, returns.max) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
    }

    /// A finished episode of env `env`, counted for its object as well when the run has
    /// several ([`Self::add_episode`] counts it overall).
    pub fn add_object_episode(&mut self, objects: &TrainingObjects, env: usize, outcome: &EpisodeOutcome) {
        if !objects.several() {
            return;
        }
        if self.per_object.len() < objects.distinct.len() {
            self.per_object.resize(objects.distinct.len(), ObjectWindow::default());
        }
        let slot = objects.of_env.get(env).copied().unwrap_or(0);
        if let Some(w) = self.per_object.get_mut(slot) {
            w.episodes += 1;
            w.ret += outcome.episode_return;
            w.rotation += outcome.rotation_rad;
            w.successes += u64::from(outcome.success());
        }
    }

    /// The per-object columns' values, in [`TrainingObjects::columns`] order; `None` for an
    /// object with no finished episode in the window.
    pub fn object_values(&self, objects: &TrainingObjects) -> Vec<(String, Option<f64>)> {
        let columns = objects.columns();
        let mut values = Vec::with_capacity(columns.len());
        for (k, names) in columns.chunks(OBJECT_FIGURES.len()).enumerate() {
            let w = self.per_object.get(k).cloned().unwrap_or_default();
            let per_episode = |x: f64| (w.episodes > 0).then(|| x / w.episodes as f64);
            let figures = [per_episode(w.successes as f64), per_episode(w.ret), per_episode(w.rotation)];
            values.extend(names.iter().cloned().zip(figures));
        }
        values
    }

    /// One gradient update.
    pub fn add_update(&mut self, st: &UpdateStats) {
        self.updates += 1;
        self.critic_loss += st.critic_loss;
        self.actor_loss += st.actor_loss;
        self.bc_loss += st.bc_loss;
        self.alpha += st.alpha;
        self.mean_q += st.mean_q;
    }

    /// What the behaviour policy did between two snapshots of its counters.
    pub fn add_behaviour(&mut self, before: &BehaviourStats, after: &BehaviourStats) {
        self.steps += after.steps - before.steps;
        self.controller_steps += after.controller_steps - before.controller_steps;
        self.selections += after.selections - before.selections;
        self.p_psi_sum += after.p_psi_sum - before.p_psi_sum;
    }

    /// Share of the window's env steps that followed the controller.
    pub fn controller_share(&self) -> f64 {
        self.controller_steps as f64 / self.steps.max(1) as f64
    }

    /// Mean return and rotation per finished episode (0 without one).
    pub fn mean_return_and_rotation(&self) -> (f64, f64) {
        let e = self.episodes.max(1) as f64;
        (self.ret / e, self.rotation / e)
    }

    /// One metrics row: `(column, value)` in [`METRICS_HEADER`] order after `step`; `None`
    /// where the window had nothing to average (no finished episode, no update).
    /// `actor_log_std` is the actor's mean log-std at the envs' observations when the row is
    /// written (`None` for a deterministic actor).
    pub fn values(
        &self,
        episodes: u64,
        actor_log_std: Option<f64>,
        beta: f64,
        updates: u64,
        sps: f64,
    ) -> Vec<(&'static str, Option<f64>)> {
        let w = self;
        let e = w.episodes.max(1) as f64;
        let u = w.updates.max(1) as f64;
        let per_episode = |x: f64| (w.episodes > 0).then_some(x / e);
        let per_update = |x: f64| (w.updates > 0).then_some(x / u);
        vec![
            ("episodes", Some(episodes as f64)),
            ("return", per_episode(w.ret)),
            ("rotation", per_episode(w.rotation)),
            ("contacts", per_episode(w.contacts)),
            ("success", per_episode(w.successes as f64)),
            ("controller_share", Some(w.controller_share())),
            ("p_psi", (w.selections > 0).then(|| w.p_psi_sum / w.selections as f64)),
            ("switches_per_1k", Some(1000.0 * w.switches as f64 / w.steps.max(1) as f64)),
            ("critic_loss", per_update(w.critic_loss)),
            ("actor_loss", per_update(w.actor_loss)),
            ("bc_loss", per_update(w.bc_loss)),
            ("alpha", per_update(w.alpha)),
            ("mean_q", per_update(w.mean_q)),
            ("mc_return", (w.mc_return_count > 0).then(|| w.mc_return_sum / w.mc_return_count as f64)),
            ("mc_return_max", w.mc_return_max),
            (
                "mc_return_early",
                (w.mc_return_early_count > 0).then(|| w.mc_return_early_sum / w.mc_return_early_count as f64),
            ),
            ("actor_log_std", actor_log_std),
            ("beta", Some(beta)),
            ("updates", Some(updates as f64)),
            ("steps_per_s", Some(sps)),
        ]
    }
}

/// The largest share of an early step's return that may lie past the time limit: the
/// discount's weight on the steps after it.
pub(super) const EARLY_TAIL: f64 = 0.05;

/// How the metrics discount an episode's rewards (`sac.gamma`), and which of its steps are
/// early: those at least H steps before the time limit (`env.episode_length`), where
/// `gamma^H <= EARLY_TAIL`. The critic bootstraps through the time limit (only a drop is
/// terminal) while a collected return stops there, so a return of a step near the limit
/// lacks most of what the critic's Q counts; an early step's lacks at most `EARLY_TAIL` of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Discount {
    pub gamma: f64,
    /// Steps from an episode's start whose returns count as early (0 where episodes are too
    /// short for any).
    pub early_steps: usize,
}

impl Discount {
    pub fn new(gamma: f64, episode_length_steps: usize) -> Self {
        // Step t (from 0) is early when gamma^(T - t) <= EARLY_TAIL, t <= T - H.
        let horizon = if gamma > 0.0 && gamma < 1.0 {
            (EARLY_TAIL.ln() / gamma.ln()).ceil() as usize
        } else if gamma <= 0.0 {
            // The formula's limit as gamma -> 0: gamma^1 = 0 <= EARLY_TAIL, a one-step horizon,
            // so every step of an episode is early.
            1
        } else {
            usize::MAX
        };
        let early_steps = episode_length_steps.checked_sub(horizon).map_or(0, |last| last + 1);
        Self { gamma, early_steps }
    }
}

/// The discounted returns `G_t = r_t + γ G_{t+1}` of an episode's steps (no bootstrap past
/// its end): sum, count and largest over every step, and sum and count over the early ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Returns {
    pub sum: f64,
    pub count: u64,
    pub max: Option<f64>,
    pub early_sum: f64,
    pub early_count: u64,
}

pub(super) fn discounted_returns(rewards: &[f32], discount: Discount) -> Returns {
    let mut g = 0.0f64;
    let mut returns =
        Returns { sum: 0.0, count: rewards.len() as u64, max: None, early_sum: 0.0, early_count: 0 };
    for (t, &r) in rewards.iter().enumerate().rev() {
        g = f64::from(r) + discount.gamma * g;
        returns.sum += g;
        returns.max = Some(returns.max.map_or(g, |m| m.max(g)));
        if t < discount.early_steps {
            returns.early_sum += g;
            returns.early_count += 1;
        }
    }
    returns
}

/// The CSV fields of a metrics row: counts whole, speed to 0.1, the rest to 6 decimals,
/// empty where the window had nothing to average.
pub(super) fn csv_fields(step: u64, values: &[(&str, Option<f64>)]) -> Vec<String> {
    let mut fields = vec![step.to_string()];
    fields.extend(values.iter().map(|(name, v)| match (*name, v) {
        (_, None) => String::new(),
        ("episodes" | "updates", Some(x)) => format!("{x:.0}"),
        ("steps_per_s", Some(x)) => format!("{x:.1}"),
        (_, Some(x)) => format!("{x:.6}"),
    }));
    fields
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_columns_match_the_csv_header() {
        let names: Vec<&str> =
            Window::default().values(0, None, 0.0, 0, 0.0).iter().map(|(n, _)| *n).collect();
        assert_eq!(format!("step,{}", names.join(",")), METRICS_HEADER);
    }

    #[test]
    fn a_run_on_several_objects_gets_each_objects_columns_and_figures() {
        use ObjectShape::{Cube, Sphere};
        let one = TrainingObjects::new(&[Cube, Cube], 4);
        assert!(!one.several() && one.columns().is_empty());
        assert_eq!(one.metrics_header(), METRICS_HEADER);
        let mut w = Window::default();
        let outcome = |ret: f64, rotation_rad: f64| EpisodeOutcome {
            episode_return: ret,
            rotation_rad,
            ..EpisodeOutcome::default()
        };
        w.add_object_episode(&one, 1, &outcome(1.0, 7.0));
        assert!(w.per_object.is_empty(), "one object: nothing per object");

        // Envs 0, 2 hold the cube, 1, 3 the sphere.
        let two = TrainingObjects::new(&[Cube, Sphere], 4);
        assert_eq!(
            two.metrics_header(),
            format!(
                "{METRICS_HEADER},cube_success,cube_return,cube_rotation,sphere_success,sphere_return,sphere_rotation"
            )
        );
        w.add_object_episode(&two, 1, &outcome(2.0, 7.0));
        w.add_object_episode(&two, 3, &outcome(4.0, 1.0));
        let values = w.object_values(&two);
        let names: Vec<&str> = values.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, two.columns());
        // The cube had no episode; the sphere's two average (one turned 2 pi, one did not).
        assert_eq!(values[0].1, None);
        assert_eq!(
            &values[3..].iter().map(|(_, v)| *v).collect::<Vec<_>>(),
            &[Some(0.5), Some(3.0), Some(4.0)]
        );
    }

    #[test]
    fn discounted_returns_bootstrap_nothing_past_the_end() {
        let half = Discount { gamma: 0.5, early_steps: 1 };
        let r = discounted_returns(&[1.0, 0.0, 2.0], half);
        // G = [1 + 0.5 * (0 + 0.5 * 2), 0 + 0.5 * 2, 2] = [1.5, 1, 2]; the first is early.
        assert_eq!((r.sum, r.count, r.max), (4.5, 3, Some(2.0)));
        assert_eq!((r.early_sum, r.early_count), (1.5, 1));
        let none = discounted_returns(&[], Discount { gamma: 0.9, early_steps: 5 });
        assert_eq!((none.sum, none.count, none.max, none.early_count), (0.0, 0, None, 0));
    }

    #[test]
    fn early_steps_leave_at_most_the_tail_past_the_time_limit() {
        // 0.99^299 = 0.0495 <= 0.05 < 0.99^298: steps 0..=101 of 400 are early.
        assert_eq!(Discount::new(0.99, 400).early_steps, 102);
        assert!(0.99f64.powi(400 - 101) <= EARLY_TAIL && 0.99f64.powi(400 - 102) > EARLY_TAIL);
        // Episodes shorter than the horizon have no early step; gamma 0 makes every step one.
        assert_eq!(Discount::new(0.99, 298).early_steps, 0);
        assert_eq!(Discount::new(0.99, 299).early_steps, 1);
        assert_eq!(Discount::new(0.0, 10).early_steps, 10);
        assert_eq!(Discount::new(1.0, 10).early_steps, 0);

        // Steady reward 1 over 400 steps: an early return is within 5% of 1 / (1 - 0.99) =
        // 100, while the mean over every step is about 0.757 of it.
        let discount = Discount::new(0.99, 400);
        let r = discounted_returns(&[1.0; 400], discount);
        let (all, early) = (r.sum / r.count as f64, r.early_sum / r.early_count as f64);
        let untruncated = 1.0 / (1.0 - 0.99);
        let expected = |steps: i32| {
            (0..steps).map(|t| untruncated * (1.0 - 0.99f64.powi(400 - t))).sum::<f64>() / f64::from(steps)
        };
        assert!((all - expected(400)).abs() < 1e-6 && (75.0..76.5).contains(&all), "{all}");
        assert!((early - expected(102)).abs() < 1e-6 && early >= 95.0, "{early}");
    }
}
