//! The gait diagram of one episode (`vge eval --plot F.png`): each finger's contact with the
//! object as bars over time, above the object's rotation about z. Finger gaiting shows as
//! fingers taking turns to let go while the rotation keeps climbing.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::plot::{PlotError, draw_err};
use vge_run::eval::{EvalError, GaitTrace};

/// The area one chart is drawn on.
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// One episode's diagram: 1400 x 700 pixels.
pub const DIAGRAM_PX: (u32, u32) = (1400, 700);
/// One object's panel in [`plot_stacked`]: 1400 x 560 pixels, so five fit a page.
pub const STACKED_PANEL_PX: (u32, u32) = (1400, 560);

/// Draws `trace` into a PNG at `out`; `title` goes above the contacts.
pub fn plot(trace: &GaitTrace, title: &str, out: &Path) -> Result<(), PlotError> {
    crate::plot::prepare_png(out)?;
    let root = BitMapBackend::new(out, DIAGRAM_PX).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    draw_panel(&root, trace, title, duration_s(trace))?;
    root.present().map_err(draw_err)
}

/// Draws several episodes into one PNG at `out`, one panel under the other (a policy of
/// several objects: its gait on each), on one time axis: an early drop shows as short.
pub fn plot_stacked(episodes: &[Episode], out: &Path) -> Result<(), PlotError> {
    crate::plot::prepare_png(out)?;
    let (width, height) = STACKED_PANEL_PX;
    let panels = u32::try_from(episodes.len()).unwrap_or(u32::MAX).max(1);
    let root = BitMapBackend::new(out, (width, height.saturating_mul(panels))).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    let t_end = episodes.iter().map(|e| duration_s(&e.trace)).fold(0.0, f64::max);
    for (area, episode) in root.split_evenly((episodes.len().max(1), 1)).iter().zip(episodes) {
        draw_panel(area, &episode.trace, &episode.title, t_end)?;
    }
    root.present().map_err(draw_err)
}

/// The episode's length in seconds (at least one step).
fn duration_s(trace: &GaitTrace) -> f64 {
    let dt = f64::from(trace.dt_s);
    (trace.tip_contacts.len() as f64 * dt).max(dt)
}

/// Contacts above rotation, on the upper 47% and the rest of `area`, from 0 to `t_end` s.
fn draw_panel(area: &Area, trace: &GaitTrace, title: &str, t_end: f64) -> Result<(), PlotError> {
    let (_, height) = area.dim_in_pixel();
    let (top, bottom) = area.split_vertically(height * 47 / 100);
    draw_contacts(&top, trace, title, t_end)?;
    draw_rotation(&bottom, trace, t_end)
}

/// Contacts: finger f's bar spans [f + 0.15, f + 0.85] wherever it touches.
fn draw_contacts(area: &Area, trace: &GaitTrace, title: &str, t_end: f64) -> Result<(), PlotError> {
    let dt = f64::from(trace.dt_s);
    let fingers = &trace.finger_names;
    let mut contacts = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 22))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, 0.0..fingers.len() as f64)
        .map_err(draw_err)?;
    contacts
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(fingers.len() * 2 + 1)
        .y_label_formatter(&|y| {
            let i = (y - 0.5).round();
            if (y - 0.5 - i).abs() < 1e-6 && (0.0..fingers.len() as f64).contains(&i) {
                fingers[i as usize].clone()
            } else {
                String::new()
            }
        })
        .x_desc("time (s)")
        .draw()
        .map_err(draw_err)?;
    for f in 0..fingers.len() {
        let color = Palette99::pick(f).to_rgba();
        let y = f as f64;
        contacts
            .draw_series(contact_runs(&trace.tip_contacts, f).into_iter().map(|(a, b)| {
                Rectangle::new([(a as f64 * dt, y + 0.15), (b as f64 * dt, y + 0.85)], color.filled())
            }))
            .map_err(draw_err)?;
    }
    Ok(())
}

/// The runs of steps `[start, end)` in which finger `f` touches the object.
fn contact_runs(tip_contacts: &[Vec<bool>], f: usize) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut start = None;
    for (k, c) in tip_contacts.iter().enumerate() {
        match (c.get(f).copied().unwrap_or(false), start) {
            (true, None) => start = Some(k),
            (false, Some(s)) => {
                runs.push((s, k));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        runs.push((s, tip_contacts.len()));
    }
    runs
}

/// Rotation, with the 2 pi of the success test marked.
fn draw_rotation(area: &Area, trace: &GaitTrace, t_end: f64) -> Result<(), PlotError> {
    let dt = f64::from(trace.dt_s);
    let rot_max = trace.rotation_rad.iter().copied().fold(2.0 * std::f64::consts::PI, f64::max);
    let rot_min = trace.rotation_rad.iter().copied().fold(0.0, f64::min);
    let mut rotation = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, rot_min..rot_max * 1.05)
        .map_err(draw_err)?;
    rotation
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("object rotation about z (rad)")
        .draw()
        .map_err(draw_err)?;
    rotation
        .draw_series(LineSeries::new(
            trace.rotation_rad.iter().enumerate().map(|(k, r)| ((k + 1) as f64 * dt, *r)),
            BLUE.stroke_width(2),
        ))
        .map_err(draw_err)?;
    let two_pi = 2.0 * std::f64::consts::PI;
    rotation
        .draw_series(DashedLineSeries::new([(0.0, two_pi), (t_end, two_pi)], 8, 6, BLACK.stroke_width(1)))
        .map_err(draw_err)?
        .label("2 pi: a success")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    rotation
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(draw_err)
}

/// Why one episode's gait diagram could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum DrawEpisodeError {
    #[error(transparent)]
    Eval(#[from] EvalError),
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// One episode traced for a diagram, with its title.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    pub trace: GaitTrace,
    pub title: String,
}

/// Runs the episode with env seed `seed` of the policy in `bytes` on `env`, titled with
/// `label` (the policy's file), the object and what the episode did.
pub fn trace_episode(
    bytes: &[u8],
    env: &vge_sim::EnvConfig,
    seed: u64,
    label: &str,
) -> Result<Episode, EvalError> {
    let trace = vge_run::eval::trace_policy_bytes(bytes, env, seed)?;
    let o = &trace.outcome;
    let title = format!(
        "{label}: the {}, episode seed {seed}, {:.1} rad in {:.1} s, {} contact switches{}",
        env.object.shape,
        o.rotation_rad,
        o.length as f32 * trace.dt_s,
        o.contact_switches,
        if o.terminated { ", dropped" } else { "" }
    );
    Ok(Episode { trace, title })
}

/// [`trace_episode`] and its diagram into `out`.
pub fn draw_episode(
    bytes: &[u8],
    env: &vge_sim::EnvConfig,
    seed: u64,
    label: &str,
    out: &Path,
) -> Result<(), DrawEpisodeError> {
    let episode = trace_episode(bytes, env, seed, label)?;
    plot(&episode.trace, &episode.title, out)?;
    Ok(())
}

/// `F.png` -> `F-<object>.png`: one object's diagram beside the figure of all of them.
pub fn per_object_png(stacked: &Path, object: vge_sim::ObjectShape) -> PathBuf {
    let stem = stacked.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = match stacked.extension() {
        Some(ext) => format!("{stem}-{}.{}", object.name(), ext.to_string_lossy()),
        None => format!("{stem}-{}", object.name()),
    };
    stacked.with_file_name(name)
}

/// The episode with env seed `seed` on each panel's env: one diagram per panel at its path
/// and, for more than one panel, all of them stacked in `stacked`.
pub fn draw_episodes(
    bytes: &[u8],
    panels: &[(&vge_sim::EnvConfig, &Path)],
    seed: u64,
    label: &str,
    stacked: &Path,
) -> Result<(), DrawEpisodeError> {
    let mut episodes = Vec::with_capacity(panels.len());
    for &(env, out) in panels {
        let episode = trace_episode(bytes, env, seed, label)?;
        plot(&episode.trace, &episode.title, out)?;
        episodes.push(episode);
    }
    if episodes.len() > 1 {
        plot_stacked(&episodes, stacked)?;
    }
    Ok(())
}
