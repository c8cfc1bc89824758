//! report.png: error against speed, one point per configuration, two panels per mesh.
//!
//! Left: rays answered wrongly per million (wrong hits on the oracle's sample and on
//! the hard rays, plus leaks from the closed solids) against Mrays/s; right: the
//! largest |Δt|/t against Mrays/s. Mrays/s is the geometric mean of the three standard
//! sets (one thread), with a bar from the geometric mean of the slowest runs to that
//! of the fastest. Both error axes are logarithmic; a zero is drawn on the axis's
//! floor, labelled 0. The speed axis is linear, so it always has ticks.
//! Text uses a subset of DejaVu Sans the binary carries, so the chart looks the same
//! on every machine, fonts installed or not.

use plotters::prelude::*;
use plotters::style::FontStyle;

use super::{MeshReport, Row};

/// The geometric mean of positive numbers.
fn geo_mean(xs: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = xs.fold((0.0, 0usize), |(s, n), x| (s + x.max(1e-9).ln(), n + 1));
    (sum / n.max(1) as f64).exp()
}

/// DejaVu Sans, subset to the characters the chart draws (assets/DejaVuSans-LICENSE.txt).
const FONT: &[u8] = include_bytes!("../../../../assets/DejaVuSans-subset.ttf");
const FAMILY: &str = "sans-serif";

/// Pixels of one panel.
const PANEL: (u32, u32) = (640, 440);

/// One configuration's point.
struct Point {
    label: String,
    group: &'static str,
    mrays: f64,
    /// The geometric means of the slowest and the fastest runs.
    spread: (f64, f64),
    /// Wrong answers per million rays (sample + leaks).
    failures: f64,
    max_relative_dt: f64,
}

impl Point {
    fn of(row: &Row) -> Point {
        let speeds = row.speeds();
        Point {
            label: label(row),
            group: row.knob,
            mrays: geo_mean(speeds.iter().map(|s| s.median)),
            spread: (geo_mean(speeds.iter().map(|s| s.min)), geo_mean(speeds.iter().map(|s| s.max))),
            failures: row.errors.per_million() + row.hard_wrong_per_million + row.leaks_per_million,
            max_relative_dt: row.errors.max_relative_dt,
        }
    }
}

/// A short name for a row: its setting, prefixed by the knob where the setting is a
/// bare number.
fn label(row: &Row) -> String {
    match row.knob {
        "defaults" => "defaults".into(),
        // "obvhs CWBVH (...)" → "obvhs", "Embree 3 BVH, fast mode" → "Embree fast".
        "peer" => {
            let name = row.setting.split(' ').next().unwrap_or("peer");
            match row.setting.rsplit_once(", ") {
                Some((_, mode)) => format!("{name} {}", mode.trim_end_matches(" mode")),
                None => name.into(),
            }
        }
        "bake margin" => format!("margin {}", row.setting),
        "depth limit" => format!("depth {}", row.setting),
        "leaf target" => format!("leaf {}", row.setting),
        _ => row.setting.clone(),
    }
}

fn colour(group: &str) -> RGBColor {
    match group {
        "defaults" => RGBColor(0, 0, 0),
        "triangle test" => RGBColor(214, 39, 40),
        "exit face" => RGBColor(31, 119, 180),
        "bake margin" => RGBColor(44, 160, 44),
        "depth limit" => RGBColor(255, 127, 14),
        "leaf target" => RGBColor(148, 103, 189),
        "octree" => RGBColor(23, 190, 207),
        "baseline" => RGBColor(140, 86, 75),
        _ => RGBColor(127, 127, 127),
    }
}

/// The chart as PNG bytes.
pub(super) fn png(reports: &[MeshReport]) -> anyhow::Result<Vec<u8>> {
    // Registering again replaces the same font: harmless.
    plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
        .map_err(|_| anyhow::anyhow!("the embedded chart font does not parse"))?;
    let rows = reports.len().max(1) as u32;
    let (w, h) = (2 * PANEL.0, rows * PANEL.1);
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw(&mut rgb, (w, h), reports).map_err(|e| anyhow::anyhow!("drawing the chart: {e}"))?;
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header()?.write_image_data(&rgb)?;
    Ok(out)
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn draw(rgb: &mut [u8], size: (u32, u32), reports: &[MeshReport]) -> DrawResult {
    let root = BitMapBackend::with_buffer(rgb, size).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((reports.len().max(1), 2));
    for (r, report) in reports.iter().enumerate() {
        let points: Vec<Point> = report.rows.iter().map(Point::of).collect();
        let title = |what: &str| format!("{}: {what}", report.name);
        panel(
            &panels[2 * r],
            &title("wrong answers (random, hard) + leaks per M rays"),
            "wrong / M rays",
            &points,
            |p| p.failures,
        )?;
        panel(&panels[2 * r + 1], &title("largest |Δt|/t on the sample"), "max |Δt|/t", &points, |p| {
            p.max_relative_dt
        })?;
    }
    root.present()?;
    Ok(())
}

/// One panel: `error` of each point (log scale, zero on the floor) against Mrays/s.
fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    y_name: &str,
    points: &[Point],
    error: impl Fn(&Point) -> f64,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let positive = points.iter().map(&error).filter(|&e| e > 0.0);
    let (lo, hi) = positive.fold((f64::INFINITY, 0.0f64), |(l, h), e| (l.min(e), h.max(e)));
    // A decade below the smallest non-zero error is the floor where zeros sit.
    let (floor, top) =
        if hi > 0.0 { (10f64.powf(lo.log10().floor() - 1.0), 10f64.powf(hi.log10().ceil())) } else { (0.1, 10.0) };
    // A linear speed axis from zero: it always has ticks (a log axis over less than a
    // decade may have none), and the spreads read as lengths.
    let x_hi = points.iter().map(|p| p.spread.1.max(p.mrays)).fold(0.0f64, f64::max);
    let x_hi = if x_hi > 0.0 { x_hi * 1.25 } else { 10.0 };
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FAMILY, 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..x_hi, (floor..top).log_scale())?;
    let is_floor = move |v: &f64| *v <= floor * 1.0001;
    chart
        .configure_mesh()
        .x_desc("Mrays/s, one thread (geometric mean of the three sets)")
        .y_desc(y_name)
        .label_style((FAMILY, 12))
        .axis_desc_style((FAMILY, 13))
        .x_labels(12)
        .x_label_formatter(&|v| format!("{v:.2}"))
        .y_label_formatter(&|v| if is_floor(v) { "0".into() } else { format!("{v:.0e}") })
        .draw()?;
    let at = |p: &Point| (p.mrays, error(p).max(floor));
    // The runs' spread: a bar from the slowest to the fastest.
    chart.draw_series(points.iter().map(|p| {
        let y = error(p).max(floor);
        PathElement::new(vec![(p.spread.0, y), (p.spread.1, y)], colour(p.group).mix(0.6))
    }))?;
    chart.draw_series(points.iter().map(|p| Circle::new(at(p), 4, colour(p.group).filled())))?;
    // Configurations with the same errors and close speeds crowd together (most have
    // no error at all): each label takes the first offset, alternately above and
    // below its point, where it overlaps no label placed before it, with a leader
    // line when it had to move away.
    let mut placed: Vec<[i32; 4]> = Vec::new();
    let mut order: Vec<&Point> = points.iter().collect();
    order.sort_by(|a, b| a.mrays.total_cmp(&b.mrays));
    let (_, rows) = chart.plotting_area().get_pixel_range();
    for p in order {
        let (x, y) = chart.backend_coord(&at(p));
        let (w, h) = (LABEL_CHAR_PX * p.label.chars().count() as i32, LABEL_PX);
        let free = |dy: i32| {
            let b = [x + 6, y + dy, x + 6 + w, y + dy + h];
            let inside = rows.start <= b[1] && b[3] <= rows.end;
            (inside && !placed.iter().any(|q| b[0] < q[2] && q[0] < b[2] && b[1] < q[3] && q[1] < b[3])).then_some(b)
        };
        let (dy, b) = (0..24)
            .map(|k| if k % 2 == 0 { -16 - 7 * k } else { 4 + 7 * (k - 1) })
            .find_map(|dy| free(dy).map(|b| (dy, b)))
            .unwrap_or((-16, [x + 6, y - 16, x + 6 + w, y - 16 + h]));
        placed.push(b);
        let c = colour(p.group);
        // Offsets from the point, in pixels.
        let text = Text::new(p.label.clone(), (6, dy), (FAMILY, 11).into_font().color(&c));
        // The leader: from the point to the label's near edge (nothing when it sits
        // beside its point).
        let end = if (-16..=4).contains(&dy) { (0, 0) } else { (6, if dy < 0 { dy + h } else { dy }) };
        let leader = PathElement::new(vec![(0, 0), end], c.mix(0.5));
        chart.plotting_area().draw(&(EmptyElement::at(at(p)) + leader + text))?;
    }
    Ok(())
}

/// Approximate width of a label's character and height of a label, in pixels.
const LABEL_CHAR_PX: i32 = 6;
const LABEL_PX: i32 = 12;
