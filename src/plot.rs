//! `modesuite plot`: training curves of one or more runs (seeds) as a PNG, in the style of the
//! MoDeSuite paper's figures: the mean over runs as a line and one standard deviation as a
//! band, episode return on the left and success rate on the right, against env steps (each
//! run's training episodes averaged over the last [`WINDOW_EPISODES`] that ended). Where a
//! run folder has an `evals.jsonl` (the held-out evaluations `scripts/results.py` appends: one
//! JSON object per line with `env_steps` and `success_rate`), the success panel also shows each
//! evaluation as a dot and their mean over the runs as an orange line.
//!
//! Lines, bands and grid are drawn by `plotters` (bitmap backend); the text (title, tick
//! values, axis names) by the renderer's built-in bitmap font, so no system font is needed.

use std::path::{Path, PathBuf};

use modesuite_learn::{read_metrics, Metrics};

use crate::make::MakeError;
use plotters::prelude::*;

/// One curve over a shared grid of env steps: mean and standard deviation over runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// Env steps.
    pub x: Vec<f64>,
    /// Mean over the runs that reached each point.
    pub mean: Vec<f64>,
    /// Population standard deviation over those runs.
    pub std: Vec<f64>,
}

/// The training curves' window: each point averages the episodes that ended in the most recent
/// iterations, back to at least this many (an iteration of 16 envs ends a few long episodes,
/// often none or one, so its own mean jumps between 0 and 100 %).
pub const WINDOW_EPISODES: u64 = 20;

/// `value` (a mean over the episodes an iteration ended) at each iteration that ended any,
/// averaged, weighted by episodes, over the most recent such iterations holding at least
/// `window` episodes (all of them until there are that many).
pub fn rolling(
    run: &[Metrics],
    value: fn(&Metrics) -> Option<f64>,
    window: u64,
) -> Vec<(f64, f64)> {
    let points: Vec<(f64, f64, u64)> = run
        .iter()
        .filter_map(|m| {
            value(m)
                .filter(|v| v.is_finite())
                .map(|v| (m.env_steps as f64, v, m.episodes.max(1)))
        })
        .collect();
    (0..points.len())
        .map(|i| {
            let (mut sum, mut n) = (0.0, 0u64);
            for &(_, v, k) in points[..=i].iter().rev() {
                sum += v * k as f64;
                n += k;
                if n >= window {
                    break;
                }
            }
            (points[i].0, sum / n as f64)
        })
        .collect()
}

/// The curve of `value` over `runs` (each a run's metrics in order), each run's values averaged
/// over `window` episodes ([`rolling`]), on `points` env-step values from the first logged step
/// to the last step every run reached; each run counts with its latest value at or before each
/// point. `None` when no run has the value.
pub fn curve(
    runs: &[Vec<Metrics>],
    value: fn(&Metrics) -> Option<f64>,
    window: u64,
    points: usize,
) -> Option<Curve> {
    let series: Vec<Vec<(f64, f64)>> = runs.iter().map(|r| rolling(r, value, window)).collect();
    series_curve(&series, points)
}

/// [`curve`] of series of `(env steps, value)` points in order (non-finite values and empty
/// series are left out).
pub fn series_curve(series: &[Vec<(f64, f64)>], points: usize) -> Option<Curve> {
    let series: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| {
            s.iter()
                .copied()
                .filter(|(_, v)| v.is_finite())
                .collect::<Vec<_>>()
        })
        .filter(|s| !s.is_empty())
        .collect();
    if series.is_empty() {
        return None;
    }
    let start = series.iter().map(|s| s[0].0).fold(f64::INFINITY, f64::min);
    let end = series
        .iter()
        .map(|s| s[s.len() - 1].0)
        .fold(f64::INFINITY, f64::min);
    let points = points.max(2);
    let mut out = Curve {
        x: Vec::with_capacity(points),
        mean: Vec::with_capacity(points),
        std: Vec::with_capacity(points),
    };
    for k in 0..points {
        let x = start + (end - start) * k as f64 / (points - 1) as f64;
        let vals: Vec<f64> = series
            .iter()
            .filter_map(|s| s.iter().take_while(|(e, _)| *e <= x).last().map(|p| p.1))
            .collect();
        if vals.is_empty() {
            continue;
        }
        let n = vals.len() as f64;
        let mean = vals.iter().sum::<f64>() / n;
        let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        out.x.push(x);
        out.mean.push(mean);
        out.std.push(var.sqrt());
    }
    Some(out)
}

/// One held-out evaluation of a run, as `scripts/results.py` appends it to the run's
/// `evals.jsonl` (other keys are ignored).
#[derive(Debug, Clone, serde::Deserialize)]
struct Evaluation {
    env_steps: u64,
    success_rate: f64,
}

/// The held-out evaluations of each run folder as `(env steps, success in %)` in file order:
/// empty for a folder without `evals.jsonl`; a line that is not an evaluation is an error naming
/// the file and line.
pub fn load_evaluations(dirs: &[PathBuf]) -> Result<Vec<Vec<(f64, f64)>>, String> {
    dirs.iter()
        .map(|d| {
            let path = d.join("evals.jsonl");
            let text = match std::fs::read_to_string(&path) {
                Ok(t) => t,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
                Err(e) => return Err(format!("{}: {e}", path.display())),
            };
            text.lines()
                .enumerate()
                .filter(|(_, l)| !l.trim().is_empty())
                .map(|(i, l)| {
                    serde_json::from_str::<Evaluation>(l)
                        .map(|e| (e.env_steps as f64, 100.0 * e.success_rate))
                        .map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))
                })
                .collect()
        })
        .collect()
}

/// Reads the `metrics.jsonl` of each run folder.
pub fn load_runs(dirs: &[PathBuf]) -> Result<Vec<Vec<Metrics>>, String> {
    dirs.iter()
        .map(|d| read_metrics(&d.join("metrics.jsonl")).map_err(|e| e.to_string()))
        .collect()
}

const W: u32 = 1200;
const H: u32 = 480;

/// Draws the return and success curves of the runs in `dirs` into `out` (PNG), titled
/// `title`; written atomically. Errors: [`MakeError::Input`] for run folders without usable
/// metrics, [`MakeError::Runtime`] when drawing or writing fails.
pub fn plot(dirs: &[PathBuf], out: &Path, title: &str) -> Result<(), MakeError> {
    if dirs.is_empty() {
        return Err(MakeError::Input(
            "plot: give at least one run folder".into(),
        ));
    }
    let runs = load_runs(dirs).map_err(MakeError::Input)?;
    let evals = load_evaluations(dirs).map_err(MakeError::Input)?;
    let ret = curve(&runs, |m| m.return_mean, WINDOW_EPISODES, 200);
    let succ = curve(
        &runs,
        |m| m.success_rate.map(|s| 100.0 * s),
        WINDOW_EPISODES,
        200,
    );
    let held_out = Held {
        mean: series_curve(&evals, 200),
        points: evals.concat(),
    };
    if ret.is_none() && succ.is_none() {
        return Err(MakeError::Input(format!(
            "plot: no finished episodes in the metrics of {}",
            dirs.iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    let mut buf = vec![255u8; (W * H * 3) as usize];
    let mut labels = Labels::new();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area();
        let (left, right) = root.split_horizontally(W / 2);
        let none = Held::default();
        let panels = [
            (left, ret.as_ref(), "episode return", None, &none),
            (
                right,
                succ.as_ref(),
                "success rate (%)",
                Some((0.0, 100.0)),
                &held_out,
            ),
        ];
        for (area, c, name, fixed, held) in panels {
            let Some(c) = c else { continue };
            draw_panel(&area, c, fixed, name, held, &mut labels)
                .map_err(|e| MakeError::Runtime(format!("plot: {e}")))?;
        }
        root.present()
            .map_err(|e| MakeError::Runtime(format!("plot: {e}")))?;
    }
    let caption = format!(
        "{title}  ({} run{})",
        dirs.len(),
        if dirs.len() == 1 { "" } else { "s" }
    );
    labels.push((
        (W as i32 - 6 * caption.len() as i32 * 2) / 2,
        4,
        caption,
        INK,
    ));
    for (x, y, text, colour) in labels {
        let (x, y) = (x.max(0) as u32, y.max(0) as u32);
        modesuite_render::hud::draw_text(&mut buf, W, H, 3, (x, y), 2, &[text], colour);
    }
    modesuite_render::video::write_png(out, W, H, &buf)
        .map_err(|e| MakeError::Runtime(e.to_string()))
}

/// Text: position, text and colour.
type Labels = Vec<(i32, i32, String, [u8; 3])>;

const INK: [u8; 3] = [20, 20, 20];
const ORANGE: [u8; 3] = [230, 110, 10];
const BLUE: [u8; 3] = [31, 119, 180];

/// The held-out evaluations drawn on a panel: every run's points and their mean over runs.
#[derive(Default)]
struct Held {
    points: Vec<(f64, f64)>,
    mean: Option<Curve>,
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    c: &Curve,
    fixed: Option<(f64, f64)>,
    name: &str,
    held: &Held,
    labels: &mut Labels,
) -> Result<(), Box<dyn std::error::Error + 'static>>
where
    DB::ErrorType: 'static,
{
    let x0 = c.x.first().copied().unwrap_or(0.0).min(0.0);
    let last_eval = held.points.iter().map(|p| p.0).fold(0.0, f64::max);
    let x1 =
        c.x.last()
            .copied()
            .unwrap_or(1.0)
            .max(last_eval)
            .max(x0 + 1.0);
    let (y0, y1) = fixed.unwrap_or_else(|| {
        let lo = c
            .mean
            .iter()
            .zip(&c.std)
            .map(|(m, s)| m - s)
            .fold(f64::INFINITY, f64::min);
        let hi = c
            .mean
            .iter()
            .zip(&c.std)
            .map(|(m, s)| m + s)
            .fold(f64::NEG_INFINITY, f64::max);
        let pad = ((hi - lo) * 0.05).max(1e-6);
        (lo - pad, hi + pad)
    });
    let mut chart = ChartBuilder::on(area)
        .margin_top(64)
        .margin_bottom(44)
        .margin_left(90)
        .margin_right(20)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    let grid = RGBColor(225, 225, 225);
    for k in 0..=5 {
        let x = x0 + (x1 - x0) * k as f64 / 5.0;
        let y = y0 + (y1 - y0) * k as f64 / 5.0;
        chart.draw_series(LineSeries::new([(x, y0), (x, y1)], grid))?;
        chart.draw_series(LineSeries::new([(x0, y), (x1, y)], grid))?;
        let (px, py) = chart.backend_coord(&(x, y0));
        // the last tick's label ends just past its tick, inside the image (it ran off the
        // right edge; a label is 12 px per character and 6 px of padding wide)
        let text = tick(x, x1 - x0);
        let shift = if k == 5 {
            12 * text.len() as i32 - 8
        } else {
            20
        };
        labels.push((px - shift, py + 8, text, INK));
        let (px, py) = chart.backend_coord(&(x0, y));
        labels.push((px - 84, py - 8, tick(y, y1 - y0), INK));
    }
    chart.draw_series(LineSeries::new(
        [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)],
        BLACK,
    ))?;
    let band: Vec<(f64, f64)> =
        c.x.iter()
            .zip(c.mean.iter().zip(&c.std))
            .map(|(x, (m, s))| (*x, (m + s).min(y1)))
            .chain(
                c.x.iter()
                    .zip(c.mean.iter().zip(&c.std))
                    .rev()
                    .map(|(x, (m, s))| (*x, (m - s).max(y0))),
            )
            .collect();
    let blue = RGBColor(BLUE[0], BLUE[1], BLUE[2]);
    chart.draw_series(std::iter::once(Polygon::new(band, blue.mix(0.25).filled())))?;
    chart.draw_series(LineSeries::new(
        c.x.iter().copied().zip(c.mean.iter().copied()),
        blue.stroke_width(2),
    ))?;
    let orange = RGBColor(ORANGE[0], ORANGE[1], ORANGE[2]);
    if let Some(m) = &held.mean {
        chart.draw_series(LineSeries::new(
            m.x.iter().copied().zip(m.mean.iter().copied()),
            orange.stroke_width(2),
        ))?;
    }
    chart.draw_series(
        held.points
            .iter()
            .map(|p| Circle::new(*p, 4, orange.filled())),
    )?;
    let (px, py) = chart.backend_coord(&(x0, y1));
    labels.push((px, py - 26, name.to_string(), INK));
    let (px, py) = chart.backend_coord(&(x1, y0));
    if !held.points.is_empty() {
        // a legend inside the panel's lower right corner
        // (the line's blue, lightened to read on the labels' dark ground)
        labels.push((
            px - 260,
            py - 48,
            "training episodes".to_string(),
            [110, 180, 240],
        ));
        labels.push((
            px - 260,
            py - 26,
            "held-out evaluations".to_string(),
            [255, 150, 60],
        ));
    }
    labels.push((px - 100, py + 26, "env steps".to_string(), INK));
    Ok(())
}

/// A tick value in a few characters, with as many decimals as a range of `span` needs
/// (1.5M, 250k, 0.35, -12.5).
fn tick(v: f64, span: f64) -> String {
    let a = v.abs();
    if span >= 5e6 || (a >= 1e6 && span >= 5e5) {
        format!("{:.1}M", v / 1e6)
    } else if span >= 5e4 {
        format!("{:.0}k", v / 1e3)
    } else if span >= 5e3 || (a >= 1e4 && span >= 500.0) {
        format!("{:.1}k", v / 1e3)
    } else {
        let decimals = (2.0 - span.max(1e-9).log10().floor()).clamp(0.0, 4.0) as usize;
        format!("{v:.decimals$}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(steps: u64, ret: f64) -> Metrics {
        serde_json::from_value(serde_json::json!({
            "algo": "ppo", "iteration": 1, "env_steps": steps, "wall_s": 1.0, "steps_per_s": 1.0,
            "episodes": 1, "return_mean": ret
        }))
        .expect("metrics")
    }

    #[test]
    fn ticks_show_the_digits_their_range_needs() {
        assert_eq!(tick(1_500_000.0, 5e6), "1.5M");
        assert_eq!(tick(250_000.0, 1e6), "250k");
        assert_eq!(tick(153_600.0, 153_600.0), "154k");
        assert_eq!(tick(12_500.0, 25_000.0), "12.5k");
        assert_eq!(tick(-1702.1, 8.0), "-1702.10");
        assert_eq!(tick(0.35, 1.0), "0.35");
        assert_eq!(tick(80.0, 100.0), "80");
    }

    #[test]
    fn rolling_means_weigh_iterations_by_their_episodes_back_to_the_window() {
        let with = |steps: u64, ret: f64, episodes: u64| Metrics {
            episodes,
            ..m(steps, ret)
        };
        let run = vec![
            with(1, 10.0, 1),
            m(2, f64::NAN),
            with(3, 20.0, 3),
            with(4, 0.0, 2),
        ];
        // window 4: the first point alone; then (10 + 3 * 20) / 4; then (3 * 20 + 2 * 0) / 5
        assert_eq!(
            rolling(&run, |m| m.return_mean, 4),
            vec![(1.0, 10.0), (3.0, 17.5), (4.0, 12.0)]
        );
        // window 1: each iteration's own mean
        assert_eq!(
            rolling(&run, |m| m.return_mean, 1),
            vec![(1.0, 10.0), (3.0, 20.0), (4.0, 0.0)]
        );
    }

    #[test]
    fn held_out_evaluations_are_read_per_run_and_located_when_wrong() {
        let root = std::env::temp_dir().join(format!("ms-plot-evals-{}", std::process::id()));
        let (a, b) = (root.join("a"), root.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        std::fs::write(
            a.join("evals.jsonl"),
            "{\"env_steps\": 100, \"success_rate\": 0.25, \"errors\": 0}\n\n{\"env_steps\": 200, \"success_rate\": 1.0}\n",
        )
        .unwrap();
        let evals = load_evaluations(&[a.clone(), b.clone()]).unwrap();
        assert_eq!(evals, vec![vec![(100.0, 25.0), (200.0, 100.0)], vec![]]);
        std::fs::write(b.join("evals.jsonl"), "{\"env_steps\": 100}\n").unwrap();
        let err = load_evaluations(&[a, b.clone()]).unwrap_err();
        assert!(
            err.starts_with(&format!("{}:1: ", b.join("evals.jsonl").display())),
            "{err}"
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn curves_average_runs_with_their_latest_value() {
        let runs = vec![
            vec![m(0, 0.0), m(100, 2.0)],
            vec![m(0, 2.0), m(50, 4.0), m(100, 6.0)],
        ];
        let c = curve(&runs, |m| m.return_mean, 1, 3).unwrap();
        assert_eq!(c.x, [0.0, 50.0, 100.0]);
        assert_eq!(c.mean, [1.0, 2.0, 4.0]);
        assert_eq!(c.std, [1.0, 2.0, 2.0]);
    }
}
