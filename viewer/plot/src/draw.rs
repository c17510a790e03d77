//! The SVG: trajectory over the map (thesis Fig. 7.6) above speed over time (Figs. 7.3–7.4).
//!
//! This is the one module that talks to `plotters`. Its SVG backend writes integer pixel
//! coordinates and no clock or random state, so the same log gives the same bytes. The backend
//! does not clip, so every shape is cut to the shown window first ([`View::clip_polygon`]).

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::log::{RunLog, Sample, SpeedPoint, Stand, speeds, stands};
use crate::scene::{Scene, View};

/// Width of the picture, pixels.
pub const WIDTH_PX: u32 = 1000;
/// Largest plotting area of the trajectory panel, pixels.
pub const MAP_MAX_PX: (u32, u32) = (915, 600);
/// Smallest height of the trajectory panel's plotting area, pixels (when the floor allows).
pub const MAP_MIN_H_PX: u32 = 320;

/// Colour of the trajectory line (of the first robot when there are several).
pub const TRAJECTORY_RGB: (u8, u8, u8) = (20, 80, 200);
/// Colours of the robots' lines, in the order of their logs (then again from the first).
pub const ROBOT_RGB: [(u8, u8, u8); 12] = [
    TRAJECTORY_RGB,
    (205, 95, 0),
    (125, 45, 175),
    (0, 130, 125),
    (185, 30, 115),
    (95, 95, 95),
    (150, 120, 0),
    (0, 150, 210),
    (120, 70, 30),
    (230, 60, 60),
    (60, 140, 40),
    (90, 90, 200),
];
/// With more robots than this, legends say "one colour per chair" instead of naming each
/// (the names are on the map, at the starts, and on the waiting timeline).
const NAMED_IN_LEGEND: usize = 4;
/// Colour of the checkpoint circles' outline and numbers.
pub const CHECKPOINT_RGB: (u8, u8, u8) = (0, 140, 70);
/// Colour of the speed line.
pub const SPEED_RGB: (u8, u8, u8) = (20, 80, 200);

const TITLE_H: u32 = 64;
const HEADING_H: u32 = 30;
const MARGIN_TOP: u32 = 6;
const MARGIN_RIGHT: u32 = 20;
const MARGIN_LEFT: u32 = 10;
const MARGIN_BOTTOM: u32 = 12;
const X_LABEL_H: u32 = 44;
const Y_LABEL_W: u32 = 60;
const SPEED_PLOT_H: u32 = 250;
/// Height of one chair's row in the waiting timeline, pixels.
const WAIT_ROW_H: u32 = 18;
/// A stand at least this long is marked on the map, seconds.
const WAIT_MARK_S: f64 = 2.0;
const FONT: &str = "sans-serif";

const INK: RGBColor = RGBColor(30, 30, 30);
/// INK at a quarter on white, as the pale bars are.
const PALE_INK: RGBColor = RGBColor(199, 199, 199);
const GRID: RGBColor = RGBColor(225, 228, 232);
const WALL_FILL: RGBColor = RGBColor(126, 148, 178);
const WALL_EDGE: RGBColor = RGBColor(62, 82, 112);
const OBSTACLE_FILL: RGBColor = RGBColor(245, 152, 40);
const OBSTACLE_EDGE: RGBColor = RGBColor(170, 90, 0);
const TARGET_FILL: RGBColor = RGBColor(190, 225, 190);
const BEACON: RGBColor = RGBColor(170, 40, 160);
const COLLISION: RGBColor = RGBColor(215, 25, 30);
const START: RGBColor = RGBColor(0, 150, 60);
const TOP_SPEED: RGBColor = RGBColor(200, 60, 40);

const CHECKPOINT: RGBColor = RGBColor(CHECKPOINT_RGB.0, CHECKPOINT_RGB.1, CHECKPOINT_RGB.2);
const SPEED: RGBColor = RGBColor(SPEED_RGB.0, SPEED_RGB.1, SPEED_RGB.2);

/// The colour of robot `k`'s lines.
fn robot_color(k: usize) -> RGBColor {
    let (r, g, b) = ROBOT_RGB[k % ROBOT_RGB.len()];
    RGBColor(r, g, b)
}

/// Why the SVG could not be drawn (in practice only a bug: the backend writes to memory).
#[derive(Debug, thiserror::Error)]
#[error("drawing the SVG: {0}")]
pub struct PlotDrawError(String);

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for PlotDrawError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        Self(e.to_string())
    }
}

/// What one picture shows.
#[derive(Debug)]
pub struct Figure<'a> {
    /// First line of the title (the recording's or log's file name, or the names of several).
    pub title: String,
    /// The robots' names and trajectories (from logs or a recording): one robot, or several
    /// in one run.
    pub logs: Vec<(String, &'a RunLog)>,
    /// Lab, obstacles and checkpoints under the trajectories.
    pub scene: &'a Scene,
}

impl Figure<'_> {
    /// Several robots: each is named in the legends and drawn in its own colour.
    fn several(&self) -> bool {
        self.logs.len() > 1
    }

    fn samples(&self) -> impl Iterator<Item = &Sample> {
        self.logs.iter().flat_map(|(_, l)| l.samples.iter())
    }
}

/// A text style whose SVG `font-size` is `px` (plotters writes size / 1.24).
fn font(px: f64) -> TextStyle<'static> {
    (FONT, px * 1.24).into_font().color(&INK)
}

fn bold(px: f64) -> TextStyle<'static> {
    (FONT, px * 1.24, FontStyle::Bold).into_font().color(&INK)
}

/// Rough width of a text in pixels, for laying out legends (no font is measured, so the
/// layout does not depend on the fonts installed).
fn text_width(text: &str, px: f64) -> i32 {
    (text.chars().count() as f64 * px * 0.56).round() as i32
}

/// Pixels per metre and the window of the floor shown, with equal scales on both axes.
fn map_window(fig: &Figure) -> (f64, View) {
    let points = fig.samples().map(|s| (s.x_m, s.y_m));
    let view = View::around(points, fig.scene);
    let bounds = view.bounds(fig.scene);
    let (wmax, hmax) = (f64::from(MAP_MAX_PX.0), f64::from(MAP_MAX_PX.1));
    let scale = (wmax / view.width().max(1e-3)).min(hmax / view.height().max(1e-3));
    // The map fills the width (more floor to the sides) but grows in height only to a
    // readable minimum: a long straight run stays a short strip, not the whole floor.
    let h_px = (view.height() * scale).clamp(f64::from(MAP_MIN_H_PX), hmax);
    let grown = view.grown_to(wmax / scale, h_px / scale, bounds.as_ref());
    // Whole pixels: the window is cut to the pixels it fills so the scales stay equal.
    let w_px = (grown.width() * scale).round().clamp(1.0, wmax);
    let h_px = (grown.height() * scale).round().clamp(1.0, hmax);
    (scale, View { x0: grown.x0, x1: grown.x0 + w_px / scale, y0: grown.y0, y1: grown.y0 + h_px / scale })
}

/// A tick step giving at most about `max_ticks` ticks over `span`.
fn tick_step(span: f64, max_ticks: f64) -> f64 {
    let raw = (span / max_ticks).max(1e-9);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag)
}

fn decimals(step: f64) -> usize {
    if step >= 1.0 { 0 } else { (-step.log10().floor()) as usize }
}

/// Draws the figure and returns the SVG text.
pub fn render(fig: &Figure) -> Result<String, PlotDrawError> {
    let (scale, view) = map_window(fig);
    let map_w = (view.width() * scale).round() as u32;
    let map_h = (view.height() * scale).round() as u32;
    let map_panel_h = HEADING_H + MARGIN_TOP + map_h + X_LABEL_H + MARGIN_BOTTOM;
    let speed_panel_h = HEADING_H + MARGIN_TOP + SPEED_PLOT_H + X_LABEL_H + MARGIN_BOTTOM;
    // Several chairs: a timeline of who stood still when (where is on the map).
    let waits: Vec<Vec<Stand>> = fig.logs.iter().map(|(_, l)| stands(&l.samples)).collect();
    let wait_panel_h = if fig.several() {
        HEADING_H + MARGIN_TOP + WAIT_ROW_H * fig.logs.len() as u32 + X_LABEL_H + MARGIN_BOTTOM
    } else {
        0
    };
    let height = TITLE_H + map_panel_h + speed_panel_h + wait_panel_h;

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH_PX, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let (title, rest) = root.split_vertically(TITLE_H);
        let (map_panel, rest) = rest.split_vertically(map_panel_h);
        let (speed_panel, wait_panel) = rest.split_vertically(speed_panel_h);
        let v: Vec<Vec<SpeedPoint>> = fig.logs.iter().map(|(_, l)| speeds(&l.samples)).collect();
        draw_title(&title, fig, &v)?;
        draw_map(&map_panel, fig, view, scale, map_w, &waits)?;
        draw_speed(&speed_panel, fig, &v)?;
        if fig.several() {
            draw_waits(&wait_panel, fig, &waits)?;
        }
        root.present()?;
    }
    Ok(svg)
}

fn draw_title(area: &DrawingArea<SVGBackend, Shift>, fig: &Figure, v: &[Vec<SpeedPoint>]) -> Result<(), PlotDrawError> {
    let first = fig.samples().map(|s| s.time_s).fold(f64::INFINITY, f64::min);
    let last = fig.samples().map(|s| s.time_s).fold(f64::NEG_INFINITY, f64::max);
    let top = v.iter().flatten().map(|p| p.speed_m_s).fold(0.0, f64::max);
    let lab = fig.scene.lab.as_ref().map_or_else(|| "no map".to_owned(), |l| format!("lab {}", l.name));
    let centre = (WIDTH_PX / 2) as i32;
    area.draw(&Text::new(fig.title.clone(), (centre, 12), bold(22.0).pos(Pos::new(HPos::Center, VPos::Top))))?;
    let driven: f64 = fig.logs.iter().map(|(_, l)| l.distance_m()).sum();
    let rows = if fig.several() {
        format!("{} robots", fig.logs.len())
    } else {
        format!("{} ticks", fig.logs.iter().map(|(_, l)| l.samples.len()).sum::<usize>())
    };
    let unplaced: usize = fig.logs.iter().map(|(_, l)| l.unplaced_rows).sum();
    let unplaced = if unplaced > 0 { format!(" ({unplaced} without a GPS fix)") } else { String::new() };
    // A recording's track does not say when a robot touched something: no count rather than 0.
    let collided = if fig.logs.iter().any(|(_, l)| l.knows_collisions()) {
        let n: usize = fig.logs.iter().map(|(_, l)| l.collision_rows()).sum();
        format!("  ·  ticks in collision: {n}")
    } else {
        String::new()
    };
    let subtitle = format!(
        "{lab}  ·  {rows}{unplaced}, {:.1} s  ·  {driven:.1} m driven  ·  top speed {top:.2} m/s{collided}",
        (last - first).max(0.0),
    );
    area.draw(&Text::new(subtitle, (centre, 42), font(14.0).pos(Pos::new(HPos::Center, VPos::Top))))?;
    Ok(())
}

/// The legend's entries for the robots' lines: each named, or for many one entry.
fn robot_keys(fig: &Figure) -> Vec<(Key, String)> {
    if fig.logs.len() > NAMED_IN_LEGEND {
        return vec![(Key::Line(robot_color(0), false), "one colour per chair".to_owned())];
    }
    fig.logs.iter().enumerate().map(|(k, (name, _))| (Key::Line(robot_color(k), false), name.clone())).collect()
}

/// One legend entry: a marker drawn at a pixel position, then its words.
enum Key {
    Line(RGBColor, bool),
    Dot(RGBColor, i32),
    Square(RGBColor),
    Ring(RGBColor),
}

/// Draws a row of legend entries right-aligned on the panel's heading line.
fn draw_legend(
    area: &DrawingArea<SVGBackend, Shift>,
    entries: &[(Key, String)],
    right: i32,
    y: i32,
) -> Result<(), PlotDrawError> {
    let px = 13.0;
    let widths: Vec<i32> = entries.iter().map(|(_, t)| 22 + text_width(t, px) + 16).collect();
    let mut x = right - widths.iter().sum::<i32>();
    for ((key, label), w) in entries.iter().zip(widths) {
        let c = (x + 8, y);
        match key {
            Key::Line(color, dashed) => {
                if *dashed {
                    area.draw(&PathElement::new(vec![(x, y), (x + 6, y)], color.stroke_width(2)))?;
                    area.draw(&PathElement::new(vec![(x + 10, y), (x + 16, y)], color.stroke_width(2)))?;
                } else {
                    area.draw(&PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(3)))?;
                }
            }
            Key::Dot(color, r) => area.draw(&Circle::new(c, *r, color.filled()))?,
            Key::Square(color) => area.draw(&Rectangle::new([(x + 2, y - 6), (x + 14, y + 6)], color.filled()))?,
            Key::Ring(color) => area.draw(&Circle::new(c, 6, color.stroke_width(2)))?,
        }
        area.draw(&Text::new(label.clone(), (x + 22, y), font(px).pos(Pos::new(HPos::Left, VPos::Center))))?;
        x += w;
    }
    Ok(())
}

fn draw_map(
    panel: &DrawingArea<SVGBackend, Shift>,
    fig: &Figure,
    view: View,
    scale: f64,
    map_w: u32,
    waits: &[Vec<Stand>],
) -> Result<(), PlotDrawError> {
    let scene = fig.scene;
    let heading_y = (HEADING_H / 2 + 4) as i32;
    panel.draw(&Text::new(
        if fig.several() { "Trajectories over the map" } else { "Trajectory over the map" },
        (MARGIN_LEFT as i32, heading_y),
        bold(16.0).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    let mut keys =
        if fig.several() { robot_keys(fig) } else { vec![(Key::Line(robot_color(0), false), "trajectory".to_owned())] };
    keys.push((Key::Dot(START, 6), "start".into()));
    keys.push((Key::Square(INK), "end".into()));
    if scene.lab.as_ref().is_some_and(|l| !l.walls.is_empty()) {
        keys.push((Key::Square(WALL_FILL), "wall".into()));
    }
    if !scene.obstacles.is_empty() {
        keys.push((Key::Square(OBSTACLE_FILL), "obstacle".into()));
    }
    if !scene.checkpoints.is_empty() {
        keys.push((Key::Ring(CHECKPOINT), "checkpoint".into()));
    }
    if fig.samples().any(|s| s.collision) {
        keys.push((Key::Dot(COLLISION, 4), "collision".into()));
    }
    let marked = |w: &&Stand| !w.last && w.seconds() >= WAIT_MARK_S;
    if fig.several() && waits.iter().flatten().any(|w| marked(&w)) {
        keys.push((Key::Ring(INK), format!("waited ≥ {WAIT_MARK_S:.0} s")));
    }
    draw_legend(panel, &keys, (WIDTH_PX - MARGIN_RIGHT) as i32, heading_y)?;

    // Centre a narrow map: the plotting area is exactly `map_w` pixels wide.
    let spare = (MAP_MAX_PX.0 - map_w.min(MAP_MAX_PX.0)) / 2;
    let mut chart = ChartBuilder::on(panel)
        .margin_top(HEADING_H + MARGIN_TOP)
        .margin_bottom(MARGIN_BOTTOM)
        .margin_left(MARGIN_LEFT + spare)
        .margin_right(MARGIN_RIGHT + spare)
        .x_label_area_size(X_LABEL_H)
        .y_label_area_size(Y_LABEL_W)
        .build_cartesian_2d(view.x0..view.x1, view.y0..view.y1)?;

    // One step for both axes, so the grid is square like the scales.
    let step = tick_step(view.width().max(view.height()), 16.0);
    let digits = decimals(step);
    let fmt = move |v: &f64| format!("{v:.digits$}");
    let labels = ((view.width() / step) as usize + 2, (view.height() / step) as usize + 2);
    draw_mesh(&mut chart, labels, (&fmt, &fmt), ("x (m)", "y (m)"))?;

    let px = |m: f64| (m * scale).round() as i32;
    if let Some(lab) = &scene.lab {
        for (k, t) in lab.targets.iter().enumerate() {
            let ring: Vec<(f64, f64)> = (0..72)
                .map(|i| {
                    let a = f64::from(i) * std::f64::consts::TAU / 72.0;
                    (t.pos.x + t.radius_m * a.cos(), t.pos.y + t.radius_m * a.sin())
                })
                .collect();
            fill(&mut chart, &view, &ring, TARGET_FILL, None)?;
            if view.contains(t.pos.x, t.pos.y) {
                let label = format!("T{k}");
                chart.draw_series(std::iter::once(Text::new(label, (t.pos.x, t.pos.y), centred(bold(12.0)))))?;
            }
        }
        for wall in &lab.walls {
            let corners: Vec<(f64, f64)> = wall.corners.iter().map(|p| (p.x, p.y)).collect();
            fill(&mut chart, &view, &corners, WALL_FILL, Some(WALL_EDGE))?;
        }
    }
    for (k, o) in scene.obstacles.iter().enumerate() {
        let corners = [(o.x0, o.y0), (o.x1, o.y0), (o.x1, o.y1), (o.x0, o.y1)];
        fill(&mut chart, &view, &corners, OBSTACLE_FILL, Some(OBSTACLE_EDGE))?;
        let (cx, cy) = ((o.x0 + o.x1) / 2.0, (o.y0 + o.y1) / 2.0);
        if view.contains(cx, cy) {
            chart.draw_series(std::iter::once(Text::new(obstacle_name(k), (cx, cy), centred(bold(13.0)))))?;
        }
    }
    if let Some(lab) = &scene.lab {
        draw_lab_outline(&mut chart, &view, lab.width_m, lab.height_m)?;
        for (k, b) in lab.beacons.iter().enumerate() {
            if view.contains(b.pos.x, b.pos.y) {
                let marker = EmptyElement::at((b.pos.x, b.pos.y))
                    + Circle::new((0, 0), 5, BEACON.filled())
                    + Text::new(format!("B{k}"), (7, -7), font(12.0).color(&BEACON));
                chart.draw_series(std::iter::once(marker))?;
            }
        }
    }
    let cp = CHECKPOINT;
    for (k, c) in scene.checkpoints.iter().enumerate() {
        let r = px(c.radius).max(3);
        let at = (c.x, c.y);
        chart.draw_series([Circle::new(at, r, cp.mix(0.12).filled()), Circle::new(at, r, cp.stroke_width(2))])?;
        let number = format!("{}", k + 1);
        let label = if r >= 9 {
            Text::new(number, (0, 0), centred(bold(14.0).color(&CHECKPOINT)))
        } else {
            Text::new(number, (r + 3, -r - 3), bold(14.0).color(&CHECKPOINT).pos(Pos::new(HPos::Left, VPos::Bottom)))
        };
        chart.draw_series(std::iter::once(EmptyElement::at(at) + label))?;
    }

    for (k, (name, log)) in fig.logs.iter().enumerate() {
        draw_track(&mut chart, &log.samples, robot_color(k), scale, fig.several().then_some(name.as_str()))?;
    }
    if fig.several() {
        // Where chairs waited (not where they ended): a ring in the chair's colour, wider for a
        // longer wait.
        for (k, w) in waits.iter().enumerate() {
            let rings = w.iter().filter(marked).filter(|w| view.contains(w.x_m, w.y_m)).map(|w| {
                let r = (4.0 + 2.0 * w.seconds().sqrt()).clamp(6.0, 18.0) as i32;
                Circle::new((w.x_m, w.y_m), r, robot_color(k).stroke_width(2))
            });
            chart.draw_series(rings)?;
        }
    }
    Ok(())
}

/// Several chairs: one row per chair, a bar for each time it stood still (where is on the
/// map): a wait at a doorway, a deadlock, or (pale, to the end) where it stopped for good.
fn draw_waits(panel: &DrawingArea<SVGBackend, Shift>, fig: &Figure, waits: &[Vec<Stand>]) -> Result<(), PlotDrawError> {
    let heading_y = (HEADING_H / 2 + 4) as i32;
    panel.draw(&Text::new(
        "Who stood still when",
        (MARGIN_LEFT as i32, heading_y),
        bold(16.0).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    let total: f64 = waits.iter().flatten().filter(|w| !w.last).map(Stand::seconds).sum();
    let keys = vec![
        (Key::Square(INK), format!("stood still ≥ 1 s ({total:.0} s in all)")),
        (Key::Square(PALE_INK), "stopped for good (arrived, or stuck)".into()),
    ];
    draw_legend(panel, &keys, (WIDTH_PX - MARGIN_RIGHT) as i32, heading_y)?;
    let (t0, t1) = time_span(fig);
    let rows = fig.logs.len();
    let mut chart = time_chart(panel, t0..t1, 0.0..rows as f64)?;
    let xs = tick_step(t1 - t0, 12.0);
    let xd = decimals(xs);
    let names: Vec<&str> = fig.logs.iter().map(|(n, _)| n.as_str()).collect();
    // Row k (top to bottom) spans y from rows − k − 1 to rows − k; its name sits at its middle.
    let name_of = |y: &f64| {
        let k = rows as f64 - y - 0.5;
        if (k - k.round()).abs() < 1e-6 && k >= 0.0 {
            names.get(k.round() as usize).map_or(String::new(), |n| (*n).to_owned())
        } else {
            String::new()
        }
    };
    chart
        .configure_mesh()
        .x_labels(((t1 - t0) / xs) as usize + 2)
        .x_label_formatter(&|v: &f64| format!("{v:.xd$}"))
        .y_labels(rows * 2 + 1)
        .y_label_formatter(&name_of)
        .disable_y_mesh()
        .light_line_style(GRID)
        .bold_line_style(GRID)
        .axis_style(INK)
        .x_desc("time (s)")
        .label_style(font(12.0))
        .axis_desc_style(font(14.0))
        .draw()?;
    for (k, w) in waits.iter().enumerate() {
        let (lo, hi) = ((rows - k - 1) as f64 + 0.15, (rows - k) as f64 - 0.15);
        let color = robot_color(k);
        chart.draw_series(w.iter().map(|w| {
            let fill = if w.last { color.mix(0.25).filled() } else { color.filled() };
            Rectangle::new([(w.from_s, lo), (w.to_s, hi)], fill)
        }))?;
    }
    Ok(())
}

/// One robot's trajectory with its collisions, start and end; with several robots the start
/// carries the robot's `name` instead of the word "start", and the end no word.
fn draw_track(
    chart: &mut MapChart,
    samples: &[Sample],
    color: RGBColor,
    scale: f64,
    name: Option<&str>,
) -> Result<(), PlotDrawError> {
    let path: Vec<(f64, f64)> = samples.iter().map(|s| (s.x_m, s.y_m)).collect();
    chart.draw_series(LineSeries::new(path.iter().copied(), color.stroke_width(2)))?;
    // One mark per place hit: rows of a long contact fall on the same pixels.
    let mut last_mark: Option<(f64, f64)> = None;
    for s in samples.iter().filter(|s| s.collision) {
        if last_mark.is_some_and(|(x, y)| ((s.x_m - x) * scale).hypot((s.y_m - y) * scale) < 3.0) {
            continue;
        }
        last_mark = Some((s.x_m, s.y_m));
        chart.draw_series(std::iter::once(Circle::new((s.x_m, s.y_m), 4, COLLISION.filled())))?;
    }
    if let (Some(first), Some(last)) = (path.first().copied(), path.last().copied()) {
        let start = EmptyElement::at(first)
            + Circle::new((0, 0), 7, START.filled())
            + Circle::new((0, 0), 7, WHITE.stroke_width(2))
            + Text::new(
                name.unwrap_or("start").to_owned(),
                (10, 10),
                bold(13.0).color(if name.is_some() { &color } else { &START }).pos(Pos::new(HPos::Left, VPos::Top)),
            );
        chart.draw_series(std::iter::once(start))?;
        let end = EmptyElement::at(last)
            + Rectangle::new([(-6, -6), (6, 6)], INK.filled())
            + Rectangle::new([(-6, -6), (6, 6)], WHITE.stroke_width(1))
            + Text::new(
                if name.is_some() { String::new() } else { "end".to_owned() },
                (10, -10),
                bold(13.0).pos(Pos::new(HPos::Left, VPos::Bottom)),
            );
        chart.draw_series(std::iter::once(end))?;
    }
    Ok(())
}

fn centred(style: TextStyle<'_>) -> TextStyle<'_> {
    style.pos(Pos::new(HPos::Center, VPos::Center))
}

/// A, B, …, Z, then 27, 28, … (the thesis names its slalom's obstacles by letter).
fn obstacle_name(k: usize) -> String {
    match u8::try_from(k) {
        Ok(k) if k < 26 => char::from(b'A' + k).to_string(),
        _ => format!("{}", k + 1),
    }
}

type MapChart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A number's label on an axis.
type Label<'f> = &'f dyn Fn(&f64) -> String;

/// Both panels' grid and axes: `labels` ticks on x and y, their formats and descriptions.
fn draw_mesh(
    chart: &mut MapChart,
    labels: (usize, usize),
    format: (Label, Label),
    desc: (&str, &str),
) -> Result<(), PlotDrawError> {
    chart
        .configure_mesh()
        .x_labels(labels.0)
        .y_labels(labels.1)
        .x_label_formatter(format.0)
        .y_label_formatter(format.1)
        .max_light_lines(1)
        .bold_line_style(GRID.stroke_width(1))
        .light_line_style(TRANSPARENT)
        .axis_style(INK.stroke_width(1))
        .label_style(font(13.0))
        .axis_desc_style(font(14.0))
        .x_desc(desc.0)
        .y_desc(desc.1)
        .draw()?;
    Ok(())
}

/// Fills the part of a polygon inside the window, with an outline if asked.
fn fill(
    chart: &mut MapChart,
    view: &View,
    polygon: &[(f64, f64)],
    color: RGBColor,
    edge: Option<RGBColor>,
) -> Result<(), PlotDrawError> {
    let clipped = view.clip_polygon(polygon);
    if clipped.len() < 3 {
        return Ok(());
    }
    chart.draw_series(std::iter::once(Polygon::new(clipped.clone(), color.filled())))?;
    if let Some(edge) = edge {
        let mut ring = clipped;
        ring.push(ring[0]);
        chart.draw_series(std::iter::once(PathElement::new(ring, edge.stroke_width(1))))?;
    }
    Ok(())
}

/// The lab's border: each side that falls inside the window, drawn thick.
fn draw_lab_outline(chart: &mut MapChart, view: &View, width: f64, height: f64) -> Result<(), PlotDrawError> {
    let eps = 1e-9;
    let (ylo, yhi) = (view.y0.max(0.0), view.y1.min(height));
    let (xlo, xhi) = (view.x0.max(0.0), view.x1.min(width));
    let mut sides = Vec::new();
    if ylo < yhi {
        for x in [0.0, width] {
            if x >= view.x0 - eps && x <= view.x1 + eps {
                sides.push(vec![(x, ylo), (x, yhi)]);
            }
        }
    }
    if xlo < xhi {
        for y in [0.0, height] {
            if y >= view.y0 - eps && y <= view.y1 + eps {
                sides.push(vec![(xlo, y), (xhi, y)]);
            }
        }
    }
    chart.draw_series(sides.into_iter().map(|s| PathElement::new(s, WALL_EDGE.stroke_width(4))))?;
    Ok(())
}

/// The first and last recorded times (a tenth of a second apart at least).
fn time_span(fig: &Figure) -> (f64, f64) {
    let t0 = fig.samples().map(|s| s.time_s).fold(f64::INFINITY, f64::min);
    let t0 = if t0.is_finite() { t0 } else { 0.0 };
    (t0, fig.samples().map(|s| s.time_s).fold(t0 + 0.1, f64::max))
}

/// A panel's chart over time: the speed and waiting panels share its margins and axes' room.
fn time_chart<'a, 'b>(
    panel: &'a DrawingArea<SVGBackend<'b>, Shift>,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<MapChart<'a, 'b>, PlotDrawError> {
    Ok(ChartBuilder::on(panel)
        .margin_top(HEADING_H + MARGIN_TOP)
        .margin_bottom(MARGIN_BOTTOM)
        .margin_left(MARGIN_LEFT)
        .margin_right(MARGIN_RIGHT)
        .x_label_area_size(X_LABEL_H)
        .y_label_area_size(Y_LABEL_W)
        .build_cartesian_2d(x, y)?)
}

fn draw_speed(
    panel: &DrawingArea<SVGBackend, Shift>,
    fig: &Figure,
    v: &[Vec<SpeedPoint>],
) -> Result<(), PlotDrawError> {
    let heading_y = (HEADING_H / 2 + 4) as i32;
    panel.draw(&Text::new(
        "Speed over time",
        (MARGIN_LEFT as i32, heading_y),
        bold(16.0).pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    let top = v.iter().flatten().map(|p| p.speed_m_s).fold(0.0, f64::max);
    let mut keys = if fig.several() { robot_keys(fig) } else { vec![(Key::Line(SPEED, false), "speed".to_owned())] };
    keys.push((Key::Line(TOP_SPEED, true), format!("top speed {top:.2} m/s")));
    let collided: Vec<(f64, f64)> = fig
        .logs
        .iter()
        .zip(v)
        .flat_map(|((_, l), v)| v.iter().filter(|p| l.samples[p.sample].collision).map(|p| (p.time_s, p.speed_m_s)))
        .collect();
    if !collided.is_empty() {
        keys.push((Key::Dot(COLLISION, 3), "collision".into()));
    }
    draw_legend(panel, &keys, (WIDTH_PX - MARGIN_RIGHT) as i32, heading_y)?;

    let (t0, t1) = time_span(fig);
    let y_max = if top > 0.0 { top * 1.15 } else { 1.0 };
    let mut chart = time_chart(panel, t0..t1, 0.0..y_max)?;
    let (xs, ys) = (tick_step(t1 - t0, 12.0), tick_step(y_max, 6.0));
    let (xd, yd) = (decimals(xs), decimals(ys));
    let xfmt = move |v: &f64| format!("{v:.xd$}");
    let yfmt = move |v: &f64| format!("{v:.yd$}");
    let labels = (((t1 - t0) / xs) as usize + 2, (y_max / ys) as usize + 2);
    draw_mesh(&mut chart, labels, (&xfmt, &yfmt), ("time (s)", "speed (m/s)"))?;

    if v.iter().all(|v| v.is_empty()) {
        let note = Text::new("fewer than two distinct ticks: no speed", ((t0 + t1) / 2.0, 0.5), centred(font(14.0)));
        chart.draw_series(std::iter::once(note))?;
        return Ok(());
    }
    chart.draw_series(DashedLineSeries::new([(t0, top), (t1, top)], 8, 5, TOP_SPEED.stroke_width(2)))?;
    for (k, v) in v.iter().enumerate() {
        let color = if fig.several() { robot_color(k) } else { SPEED };
        chart.draw_series(LineSeries::new(v.iter().map(|p| (p.time_s, p.speed_m_s)), color.stroke_width(2)))?;
    }
    chart.draw_series(collided.iter().map(|&p| Circle::new(p, 3, COLLISION.filled())))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_steps_are_round_numbers() {
        assert_eq!(tick_step(10.0, 12.0), 1.0);
        assert_eq!(tick_step(30.0, 12.0), 5.0);
        assert_eq!(tick_step(0.9, 6.0), 0.2);
        assert_eq!(decimals(0.2), 1);
        assert_eq!(decimals(5.0), 0);
    }

    #[test]
    fn obstacles_are_named_by_letter_then_number() {
        assert_eq!(obstacle_name(0), "A");
        assert_eq!(obstacle_name(25), "Z");
        assert_eq!(obstacle_name(26), "27");
    }
}
