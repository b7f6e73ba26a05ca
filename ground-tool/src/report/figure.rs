//! # Figures of stacked panels with the legend beside them (plotters, bundled font)
//!
//! Why this module: the reports' first plots drew every series into one chart with plotters'
//! in-chart legend box, which covered data, and drew "after" points over "before" points of
//! the same shape, which hid them (issue 21). A [`Figure`] here is one or more panels stacked
//! over a shared time axis, with the legend and any notes in a column to the right of the
//! panels, outside every data area. Before and after go to separate panels (same scales), so
//! neither hides the other.
//!
//! Long series are thinned to what the picture can show, never to fewer extremes: a line with
//! more points than pixel columns keeps, per column, its first, lowest, highest and last point
//! in time order (the envelope is exact); a point cloud keeps one point per occupied pixel
//! cell. Six months of 30-s housekeeping (≈ 524,000 samples per axis) then draw in well under a
//! second, and a single outlier is never thinned away.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Width of the legend column (pixels).
const LEGEND_W: u32 = 320;
/// Width of the panels' column (pixels).
const PANELS_W: u32 = 960;
/// Height of one panel (pixels).
const PANEL_H: u32 = 260;
/// Height of the figure title (pixels).
const TITLE_H: u32 = 44;
/// Height added below the last panel for its axis description (pixels).
const X_DESC_H: u32 = 24;

/// How a layer is drawn.
#[derive(Clone, Debug)]
pub enum Kind {
    /// Points: filled discs.
    Dots(Vec<(f64, f64)>),
    /// Points: open circles (for a series other layers are drawn over).
    Rings(Vec<(f64, f64)>),
    /// A polyline, broken where consecutive x differ by more than `gap` (x units).
    Line {
        /// Points in x order.
        points: Vec<(f64, f64)>,
        /// Largest x step still connected.
        gap: f64,
    },
    /// Value with a ±σ bar: (x, y, σ).
    Bars(Vec<(f64, f64, f64)>),
    /// A horizontal reference line at this y.
    HLine(f64),
}

/// One drawn layer of a panel.
#[derive(Clone, Debug)]
pub struct Layer {
    /// Legend text; `None` = not in the legend (e.g. the zero line).
    pub label: Option<String>,
    /// Colour.
    pub color: RGBColor,
    /// What is drawn.
    pub kind: Kind,
}

/// One panel: a chart with its own y axis, sharing the figure's x axis.
#[derive(Clone, Debug)]
pub struct Panel {
    /// Panel title (drawn above it).
    pub title: String,
    /// Y-axis description.
    pub y_label: String,
    /// Layers, drawn in order (later on top).
    pub layers: Vec<Layer>,
    /// `Some(q)`: the y range covers the values between the q and 1 − q quantiles (widened
    /// by half), so that a short transient does not flatten the rest; values beyond are
    /// drawn at the panel's edge and the panel's title says how many.
    pub y_quantile: Option<f64>,
}

/// A figure: panels stacked over one x axis, legend and notes in a column to their right.
#[derive(Clone, Debug)]
pub struct Figure {
    /// Title of the whole figure.
    pub title: String,
    /// X-axis description (under the last panel).
    pub x_label: String,
    /// X range; `None` = from the data.
    pub x_range: Option<(f64, f64)>,
    /// Same y range in every panel (for panels meant to be compared by eye).
    pub shared_y: bool,
    /// Panels, top to bottom.
    pub panels: Vec<Panel>,
    /// Lines of text under the legend (numbers that answer the figure's question).
    pub notes: Vec<String>,
}

fn err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{e}")
}

fn finite(x: f64, y: f64) -> bool {
    x.is_finite() && y.is_finite()
}

/// The (x, y) extents a layer covers.
fn extents(kind: &Kind) -> Vec<(f64, f64)> {
    match kind {
        Kind::Dots(p) | Kind::Rings(p) | Kind::Line { points: p, .. } => {
            p.iter().copied().filter(|&(x, y)| finite(x, y)).collect()
        }
        Kind::Bars(p) => p
            .iter()
            .filter(|(x, y, s)| finite(*x, *y) && s.is_finite())
            .flat_map(|&(x, y, s)| [(x, y - s), (x, y + s)])
            .collect(),
        Kind::HLine(_) => Vec::new(),
    }
}

fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    (lo <= hi).then_some((lo, hi))
}

/// A range with some room; a degenerate one widened to a visible width.
fn padded((lo, hi): (f64, f64), fraction: f64) -> (f64, f64) {
    let w = hi - lo;
    if w > 0.0 {
        (lo - fraction * w, hi + fraction * w)
    } else {
        let half = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        (lo - half, hi + half)
    }
}

fn y_range_of(panel: &Panel) -> Option<(f64, f64)> {
    let mut ys: Vec<f64> = panel
        .layers
        .iter()
        .flat_map(|l| extents(&l.kind).into_iter().map(|p| p.1))
        .filter(|y| y.is_finite())
        .collect();
    let lines = panel.layers.iter().filter_map(|l| match l.kind {
        Kind::HLine(y) if y.is_finite() => Some(y),
        _ => None,
    });
    match panel.y_quantile {
        Some(q) if ys.len() > 20 => {
            ys.sort_by(f64::total_cmp);
            let at = |f: f64| ys[((ys.len() - 1) as f64 * f).round() as usize];
            let (lo, hi) = (at(q), at(1.0 - q));
            let half = 0.25 * (hi - lo);
            range([lo - half, hi + half].into_iter().chain(lines))
        }
        _ => range(ys.into_iter().chain(lines)),
    }
}

/// Values of a layer beyond `y_range` moved to its edge; returns the layer and the number
/// of points moved.
fn clamped(kind: &Kind, (lo, hi): (f64, f64)) -> (Kind, usize) {
    let mut n = 0;
    let mut c = |y: f64| {
        if y < lo || y > hi {
            n += 1;
        }
        y.clamp(lo, hi)
    };
    let k = match kind {
        Kind::Dots(p) => Kind::Dots(p.iter().map(|&(x, y)| (x, c(y))).collect()),
        Kind::Rings(p) => Kind::Rings(p.iter().map(|&(x, y)| (x, c(y))).collect()),
        Kind::Line { points, gap } => Kind::Line {
            points: points.iter().map(|&(x, y)| (x, c(y))).collect(),
            gap: *gap,
        },
        // Bars are clamped where they are drawn (each end and the centre separately).
        Kind::Bars(p) => {
            for &(_, y, _) in p {
                c(y);
            }
            Kind::Bars(p.clone())
        }
        Kind::HLine(y) => Kind::HLine(*y),
    };
    (k, n)
}

/// A polyline thinned to `columns` pixel columns over `x_range`: per column its first, lowest,
/// highest and last point in x order, so the drawn envelope is exactly the full series'.
/// Segments are split where consecutive x differ by more than `gap`.
#[must_use]
pub fn thin_line(
    points: &[(f64, f64)],
    x_range: (f64, f64),
    columns: usize,
    gap: f64,
) -> Vec<Vec<(f64, f64)>> {
    let mut segments: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    let width = (x_range.1 - x_range.0).max(f64::MIN_POSITIVE);
    let column = |x: f64| ((x - x_range.0) / width * columns as f64).floor() as i64;
    // Points of the current column: first, lowest, highest, last.
    let mut bucket: Option<(i64, [(f64, f64); 4])> = None;
    let flush = |bucket: &mut Option<(i64, [(f64, f64); 4])>, out: &mut Vec<(f64, f64)>| {
        if let Some((_, [first, low, high, last])) = bucket.take() {
            let mut pts = vec![first, low, high, last];
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            pts.dedup_by(|a, b| a.0 == b.0 && a.1 == b.1);
            out.extend(pts);
        }
    };
    let mut prev_x: Option<f64> = None;
    for &(x, y) in points.iter().filter(|&&(x, y)| finite(x, y)) {
        if prev_x.is_some_and(|p| x - p > gap) {
            flush(&mut bucket, &mut current);
            segments.push(std::mem::take(&mut current));
        }
        prev_x = Some(x);
        let c = column(x);
        match &mut bucket {
            Some((col, b)) if *col == c => {
                if y < b[1].1 {
                    b[1] = (x, y);
                }
                if y > b[2].1 {
                    b[2] = (x, y);
                }
                b[3] = (x, y);
            }
            _ => {
                flush(&mut bucket, &mut current);
                bucket = Some((c, [(x, y); 4]));
            }
        }
    }
    flush(&mut bucket, &mut current);
    segments.push(current);
    segments.retain(|s| !s.is_empty());
    segments
}

/// A point cloud thinned to one point per occupied cell of a `cols` × `rows` grid over the
/// ranges (the first point of each cell, so every drawn pixel still has its point).
#[must_use]
pub fn thin_points(
    points: &[(f64, f64)],
    x_range: (f64, f64),
    y_range: (f64, f64),
    cols: usize,
    rows: usize,
) -> Vec<(f64, f64)> {
    let (wx, wy) = (
        (x_range.1 - x_range.0).max(f64::MIN_POSITIVE),
        (y_range.1 - y_range.0).max(f64::MIN_POSITIVE),
    );
    let mut seen = vec![false; cols * rows];
    let mut out = Vec::new();
    for &(x, y) in points.iter().filter(|&&(x, y)| finite(x, y)) {
        let cx = (((x - x_range.0) / wx) * cols as f64).clamp(0.0, cols as f64 - 1.0) as usize;
        let cy = (((y - y_range.0) / wy) * rows as f64).clamp(0.0, rows as f64 - 1.0) as usize;
        let cell = &mut seen[cy * cols + cx];
        if !*cell {
            *cell = true;
            out.push((x, y));
        }
    }
    out
}

/// Words of `text` in lines of at most `width` characters.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// The legend glyph of a layer, drawn centred at `(x, y)` (pixels).
fn draw_glyph(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    kind: &Kind,
    color: RGBColor,
    (x, y): (i32, i32),
) -> anyhow::Result<()> {
    match kind {
        Kind::Dots(_) => area
            .draw(&Circle::new((x, y), 4, color.filled()))
            .map_err(err),
        Kind::Rings(_) => area
            .draw(&Circle::new((x, y), 4, color.stroke_width(1)))
            .map_err(err),
        Kind::Line { .. } | Kind::HLine(_) => area
            .draw(&PathElement::new(
                vec![(x - 12, y), (x + 12, y)],
                color.stroke_width(2),
            ))
            .map_err(err),
        Kind::Bars(_) => {
            area.draw(&PathElement::new(
                vec![(x, y - 7), (x, y + 7)],
                color.stroke_width(1),
            ))
            .map_err(err)?;
            for dy in [-7, 7] {
                area.draw(&PathElement::new(
                    vec![(x - 3, y + dy), (x + 3, y + dy)],
                    color.stroke_width(1),
                ))
                .map_err(err)?;
            }
            area.draw(&Circle::new((x, y), 3, color.filled()))
                .map_err(err)
        }
    }
}

/// The legend (one entry per distinct label, in first-seen order) and the notes, in the
/// column `area`.
fn draw_legend(area: &DrawingArea<BitMapBackend<'_>, Shift>, fig: &Figure) -> anyhow::Result<()> {
    let font = ("sans-serif", 15).into_font();
    let mut seen: Vec<&str> = Vec::new();
    let mut y = 16;
    for layer in fig.panels.iter().flat_map(|p| &p.layers) {
        let Some(label) = layer.label.as_deref() else {
            continue;
        };
        if seen.contains(&label) {
            continue;
        }
        seen.push(label);
        draw_glyph(area, &layer.kind, layer.color, (20, y + 8))?;
        for line in wrap(label, 34) {
            area.draw(&Text::new(line, (40, y), font.clone()))
                .map_err(err)?;
            y += 19;
        }
        y += 6;
    }
    y += 10;
    let note_font = ("sans-serif", 14).into_font().color(&RGBColor(40, 40, 40));
    for note in &fig.notes {
        for line in wrap(note, 38) {
            area.draw(&Text::new(line, (10, y), note_font.clone()))
                .map_err(err)?;
            y += 18;
        }
        y += 6;
    }
    Ok(())
}

/// Draw `fig` to a PNG at `path`.
///
/// # Errors
/// Drawing or I/O failure (the message names the file).
pub fn draw(path: &Path, fig: &Figure) -> anyhow::Result<()> {
    super::register_font();
    let n = fig.panels.len().max(1) as u32;
    let height = TITLE_H + n * PANEL_H + X_DESC_H;
    let root = BitMapBackend::new(path, (PANELS_W + LEGEND_W, height)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let body = root.titled(&fig.title, ("sans-serif", 22)).map_err(err)?;
    let (left, right) = body.split_horizontally(PANELS_W);
    draw_legend(&right.margin(8, 0, 4, 4), fig)?;

    let x_range = fig
        .x_range
        .or_else(|| {
            range(
                fig.panels
                    .iter()
                    .flat_map(|p| &p.layers)
                    .flat_map(|l| extents(&l.kind))
                    .map(|p| p.0),
            )
        })
        .map_or((0.0, 1.0), |r| padded(r, 0.0));
    let shared = if fig.shared_y {
        range(
            fig.panels
                .iter()
                .filter_map(y_range_of)
                .flat_map(|(a, b)| [a, b]),
        )
    } else {
        None
    };
    let (panels_area, _) = left.split_vertically(n * PANEL_H + X_DESC_H);
    let heights: Vec<u32> = (0..n)
        .map(|i| PANEL_H + if i + 1 == n { X_DESC_H } else { 0 })
        .collect();
    let mut rest = panels_area;
    for (i, panel) in fig.panels.iter().enumerate() {
        let (area, below) = rest.split_vertically(heights[i]);
        rest = below;
        let last = i + 1 == fig.panels.len();
        let y_range = padded(
            shared.or_else(|| y_range_of(panel)).unwrap_or((-1.0, 1.0)),
            0.06,
        );
        let mut off_scale = 0;
        let layers: Vec<(RGBColor, Kind)> = panel
            .layers
            .iter()
            .map(|l| {
                let (k, n) = clamped(&l.kind, y_range);
                off_scale += n;
                (l.color, k)
            })
            .collect();
        let caption = if off_scale > 0 {
            format!(
                "{} — {off_scale} values off-scale, drawn at the edge",
                panel.title
            )
        } else {
            panel.title.clone()
        };
        let mut chart = ChartBuilder::on(&area)
            .caption(&caption, ("sans-serif", 16))
            .margin_left(8)
            .margin_right(16)
            .margin_top(4)
            .x_label_area_size(if last { 46 } else { 22 })
            .y_label_area_size(78)
            .build_cartesian_2d(x_range.0..x_range.1, y_range.0..y_range.1)
            .map_err(err)?;
        let mut mesh = chart.configure_mesh();
        mesh.y_desc(panel.y_label.as_str())
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .light_line_style(RGBColor(235, 235, 235));
        if last {
            mesh.x_desc(fig.x_label.as_str());
        }
        mesh.draw().map_err(err)?;
        let (cols, rows) = (PANELS_W as usize, PANEL_H as usize);
        for (color, kind) in &layers {
            let color = *color;
            match kind {
                Kind::Dots(p) => {
                    let pts = thin_points(p, x_range, y_range, cols, rows);
                    chart
                        .draw_series(
                            pts.iter()
                                .map(|&(x, y)| Circle::new((x, y), 2, color.filled())),
                        )
                        .map_err(err)?;
                }
                Kind::Rings(p) => {
                    let pts = thin_points(p, x_range, y_range, cols, rows);
                    chart
                        .draw_series(
                            pts.iter()
                                .map(|&(x, y)| Circle::new((x, y), 3, color.stroke_width(1))),
                        )
                        .map_err(err)?;
                }
                Kind::Line { points, gap } => {
                    for seg in thin_line(points, x_range, cols, *gap) {
                        chart
                            .draw_series(LineSeries::new(seg, color.stroke_width(1)))
                            .map_err(err)?;
                    }
                }
                Kind::Bars(p) => {
                    let style = color.stroke_width(1);
                    let cl = |y: f64| y.clamp(y_range.0, y_range.1);
                    // Thousands of fixes: small dots, so that what is drawn over them shows.
                    let r = if p.len() > 200 { 1 } else { 3 };
                    for &(x, y, s) in p.iter().filter(|(x, y, s)| finite(*x, *y) && s.is_finite()) {
                        chart
                            .draw_series(std::iter::once(PathElement::new(
                                vec![(x, cl(y - s)), (x, cl(y + s))],
                                style,
                            )))
                            .map_err(err)?;
                        chart
                            .draw_series(std::iter::once(Circle::new(
                                (x, cl(y)),
                                r,
                                color.filled(),
                            )))
                            .map_err(err)?;
                    }
                }
                Kind::HLine(y) => {
                    chart
                        .draw_series(LineSeries::new(
                            vec![(x_range.0, *y), (x_range.1, *y)],
                            color.stroke_width(1),
                        ))
                        .map_err(err)?;
                }
            }
        }
    }
    root.present()
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thinned_line_keeps_every_extreme_in_time_order() {
        // 100,000 samples of a slow sine with one spike, into 100 columns.
        let pts: Vec<(f64, f64)> = (0..100_000)
            .map(|i| {
                let x = f64::from(i);
                let y = if i == 43_210 {
                    50.0
                } else {
                    (x / 5000.0).sin()
                };
                (x, y)
            })
            .collect();
        let segs = thin_line(&pts, (0.0, 100_000.0), 100, 10.0);
        assert_eq!(segs.len(), 1);
        let s = &segs[0];
        assert!(s.len() <= 400, "{} points", s.len());
        assert!(s.contains(&(43_210.0, 50.0)), "the spike is kept");
        assert!(s.windows(2).all(|w| w[0].0 < w[1].0), "x order kept");
        let (lo, hi) = (
            s.iter().map(|p| p.1).fold(f64::INFINITY, f64::min),
            s.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max),
        );
        let full_lo = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert_eq!((lo, hi), (full_lo, 50.0));
    }

    #[test]
    fn a_line_breaks_at_gaps_and_points_thin_per_cell() {
        let pts = vec![(0.0, 1.0), (1.0, 2.0), (100.0, 3.0), (101.0, 4.0)];
        let segs = thin_line(&pts, (0.0, 101.0), 1000, 10.0);
        assert_eq!(
            segs,
            vec![
                vec![(0.0, 1.0), (1.0, 2.0)],
                vec![(100.0, 3.0), (101.0, 4.0)]
            ]
        );
        // Three points in one cell, one in another.
        let cloud = vec![(0.1, 0.1), (0.2, 0.2), (0.15, 0.12), (9.9, 9.9)];
        let kept = thin_points(&cloud, (0.0, 10.0), (0.0, 10.0), 10, 10);
        assert_eq!(kept, vec![(0.1, 0.1), (9.9, 9.9)]);
    }

    #[test]
    fn labels_wrap_at_word_boundaries() {
        assert_eq!(
            wrap("before (flown tables): RMS 438.3″", 20),
            vec!["before (flown", "tables): RMS 438.3″"]
        );
    }
}
