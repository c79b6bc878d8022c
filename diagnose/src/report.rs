//! A small builder for offline HTML reports: titled sections of text, tables and SVG figures
//! (drawn with the `plotters` SVG backend and inlined), one self-contained `index.html` with no
//! scripts and no network access.
//!
//! ```
//! use dynlab_diagnose::report::{LineChart, Report, Series, Table};
//!
//! let mut report = Report::new("car model against bags/car_nominal");
//! report
//!     .section("Errors")
//!     .text("One-step and 5-step errors per state dimension.")
//!     .table(Table::new(["state", "RMSE"]).row(["vx", "0.012"]));
//! report.section("Over time").chart(
//!     &LineChart::new("vx error", "time (s)", "error (m/s)")
//!         .series(Series::line("model", vec![(0.0, 0.01), (1.0, 0.02)])),
//! );
//! let html = report.to_html();
//! assert!(html.contains(">Errors</h2>"));
//! ```
//!
//! A chart that cannot be drawn (no font on the machine, empty data) becomes a note in the page
//! rather than an error: the numbers are in the tables and in `report.json` anyway.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use thiserror::Error;

/// Errors of writing a report.
#[derive(Debug, Error)]
pub enum ReportError {
    /// The output directory or file could not be written.
    #[error("writing {path}: {source}; check that the directory is writable")]
    Io {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A chart could not be drawn.
    #[error("drawing the chart \"{title}\": {reason}")]
    Plot {
        /// The chart's title.
        title: String,
        /// What went wrong.
        reason: String,
    },
}

/// Escapes text for HTML.
pub fn escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            _ => o.push(c),
        }
    }
    o
}

/// A table: a header row and rows of cells (text, escaped when written).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    /// Caption above the table.
    pub caption: Option<String>,
    /// Column names.
    pub header: Vec<String>,
    /// Rows of cells.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with these column names.
    pub fn new<I, S>(header: I) -> Self
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        Self {
            caption: None,
            header: header.into_iter().map(Into::into).collect(),
            rows: Vec::new(),
        }
    }
    /// Sets the caption.
    pub fn caption(mut self, c: impl Into<String>) -> Self {
        self.caption = Some(c.into());
        self
    }
    /// Appends a row.
    pub fn row<I, S>(mut self, cells: I) -> Self
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        self.rows.push(cells.into_iter().map(Into::into).collect());
        self
    }
    /// Appends a row in place.
    pub fn push<I, S>(&mut self, cells: I)
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        self.rows.push(cells.into_iter().map(Into::into).collect());
    }
    /// The table as fixed-width text (for terminals).
    pub fn to_text(&self) -> String {
        let ncol = self
            .rows
            .iter()
            .map(Vec::len)
            .chain([self.header.len()])
            .max()
            .unwrap_or(0);
        let mut w = vec![0usize; ncol];
        for r in std::iter::once(&self.header).chain(&self.rows) {
            for (i, c) in r.iter().enumerate() {
                w[i] = w[i].max(c.chars().count());
            }
        }
        let mut s = String::new();
        for r in std::iter::once(&self.header).chain(&self.rows) {
            let line: Vec<String> = r
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    let pad = w[i] - c.chars().count();
                    if i == 0 {
                        format!("{c}{}", " ".repeat(pad))
                    } else {
                        format!("{}{c}", " ".repeat(pad))
                    }
                })
                .collect();
            s += line.join("  ").trim_end();
            s.push('\n');
        }
        s
    }
    fn to_html(&self) -> String {
        let mut s = String::from("<table>");
        if let Some(c) = &self.caption {
            let _ = write!(s, "<caption>{}</caption>", escape(c));
        }
        s += "<thead><tr>";
        for h in &self.header {
            let _ = write!(s, "<th>{}</th>", escape(h));
        }
        s += "</tr></thead><tbody>";
        for r in &self.rows {
            s += "<tr>";
            for c in r {
                let _ = write!(s, "<td>{}</td>", escape(c));
            }
            s += "</tr>";
        }
        s += "</tbody></table>\n";
        s
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Block {
    Text(String),
    Pre(String),
    Note(String),
    Table(Table),
    Figure { caption: String, svg: String },
    Row(Vec<(String, String)>),
}

/// One titled part of a [`Report`].
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    title: String,
    blocks: Vec<Block>,
}

impl Section {
    /// The section's title.
    pub fn title(&self) -> &str {
        &self.title
    }
    /// A paragraph of text.
    pub fn text(&mut self, s: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Text(s.into()));
        self
    }
    /// Preformatted text (a terminal table, equations).
    pub fn pre(&mut self, s: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Pre(s.into()));
        self
    }
    /// A highlighted remark (a warning, a finding).
    pub fn note(&mut self, s: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Note(s.into()));
        self
    }
    /// A table.
    pub fn table(&mut self, t: Table) -> &mut Self {
        self.blocks.push(Block::Table(t));
        self
    }
    /// A figure from SVG text (inlined into the page).
    pub fn figure(&mut self, caption: impl Into<String>, svg: String) -> &mut Self {
        self.blocks.push(Block::Figure {
            caption: caption.into(),
            svg,
        });
        self
    }
    /// Draws a chart and adds it as a figure (or a note saying why it could not be drawn).
    pub fn chart(&mut self, chart: &dyn Chart) -> &mut Self {
        match chart.render_svg() {
            Ok(svg) => self.figure(chart.title(), svg),
            Err(e) => self.note(format!("figure not drawn: {e}")),
        }
    }
    /// Several charts side by side (e.g. model and baseline).
    pub fn chart_row(&mut self, charts: &[&dyn Chart]) -> &mut Self {
        let mut row = Vec::new();
        for c in charts {
            match c.render_svg() {
                Ok(svg) => row.push((c.title().to_string(), svg)),
                Err(e) => self
                    .blocks
                    .push(Block::Note(format!("figure not drawn: {e}"))),
            }
        }
        if !row.is_empty() {
            self.blocks.push(Block::Row(row));
        }
        self
    }
}

/// An HTML report: a title and sections, written as one self-contained `index.html`.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    title: String,
    sections: Vec<Section>,
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1300px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:.6em 0}td,th{border:1px solid #bbb;padding:2px 7px;text-align:right}\
td:first-child,th:first-child{text-align:left}caption{text-align:left;font-weight:bold;padding:3px 0}\
.note{background:#fff4d6;border-left:4px solid #e0a800;padding:4px 8px;margin:.5em 0}\
figure{display:inline-block;margin:.4em}figcaption{font-size:90%;color:#555}\
pre{background:#f5f5f5;padding:6px;overflow-x:auto}h2{border-bottom:1px solid #ccc;margin-top:1.6em}\
nav a{margin-right:1em}";

impl Report {
    /// An empty report.
    pub fn new(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            sections: Vec::new(),
        }
    }
    /// The report's title.
    pub fn title(&self) -> &str {
        &self.title
    }
    /// The sections so far.
    pub fn sections(&self) -> &[Section] {
        &self.sections
    }
    /// Appends a section and returns it for adding content.
    pub fn section(&mut self, title: impl Into<String>) -> &mut Section {
        self.sections.push(Section {
            title: title.into(),
            blocks: Vec::new(),
        });
        let last = self.sections.len() - 1;
        &mut self.sections[last]
    }
    /// The whole page.
    pub fn to_html(&self) -> String {
        let mut s = String::new();
        let _ = write!(
            s,
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{STYLE}</style></head><body>\n<h1>{}</h1>\n<nav>",
            escape(&self.title),
            escape(&self.title)
        );
        for (i, sec) in self.sections.iter().enumerate() {
            let _ = write!(s, "<a href=\"#s{i}\">{}</a>", escape(&sec.title));
        }
        s += "</nav>\n";
        for (i, sec) in self.sections.iter().enumerate() {
            let _ = writeln!(s, "<h2 id=\"s{i}\">{}</h2>", escape(&sec.title));
            for b in &sec.blocks {
                match b {
                    Block::Text(t) => {
                        let _ = writeln!(s, "<p>{}</p>", escape(t));
                    }
                    Block::Pre(t) => {
                        let _ = writeln!(s, "<pre>{}</pre>", escape(t));
                    }
                    Block::Note(t) => {
                        let _ = writeln!(s, "<p class=\"note\">{}</p>", escape(t));
                    }
                    Block::Table(t) => s += &t.to_html(),
                    Block::Figure { caption, svg } => {
                        let _ = writeln!(
                            s,
                            "<figure>{}<figcaption>{}</figcaption></figure>",
                            strip_xml_decl(svg),
                            escape(caption)
                        );
                    }
                    Block::Row(figs) => {
                        s += "<div>";
                        for (caption, svg) in figs {
                            let _ = write!(
                                s,
                                "<figure>{}<figcaption>{}</figcaption></figure>",
                                strip_xml_decl(svg),
                                escape(caption)
                            );
                        }
                        s += "</div>\n";
                    }
                }
            }
        }
        s += "</body></html>\n";
        s
    }
    /// Writes `dir/index.html` (creating `dir`) and returns its path.
    pub fn write(&self, dir: &Path) -> Result<PathBuf, ReportError> {
        std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let path = dir.join("index.html");
        std::fs::write(&path, self.to_html()).map_err(|source| ReportError::Io {
            path: path.clone(),
            source,
        })?;
        Ok(path)
    }
}

fn strip_xml_decl(svg: &str) -> &str {
    match svg.find("<svg") {
        Some(i) => &svg[i..],
        None => svg,
    }
}

/// Something that draws itself as SVG.
pub trait Chart {
    /// The title (also the figure caption).
    fn title(&self) -> &str;
    /// The SVG text.
    fn render_svg(&self) -> Result<String, ReportError>;
}

/// How a [`Series`] is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeriesStyle {
    /// Connected line.
    Line,
    /// Dots.
    Points,
    /// Vertical stems from zero (correlation at lags).
    Stems,
}

/// The runs of consecutive finite points: a line is broken where a point is not finite (NaN
/// separates trajectories), so no segment joins two runs.
fn finite_runs(points: &[(f64, f64)]) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut run = Vec::new();
    for &(x, y) in points {
        if x.is_finite() && y.is_finite() {
            run.push((x, y));
        } else if !run.is_empty() {
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// A named set of points of a [`LineChart`].
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points `(x, y)`; non-finite points are skipped (and break a line: put a NaN point
    /// between two trajectories drawn as one series).
    pub points: Vec<(f64, f64)>,
    /// Drawing style.
    pub style: SeriesStyle,
}

impl Series {
    /// A line.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style: SeriesStyle::Line,
        }
    }
    /// Dots.
    pub fn points(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style: SeriesStyle::Points,
        }
    }
    /// Stems from zero.
    pub fn stems(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style: SeriesStyle::Stems,
        }
    }
}

/// An x–y chart of lines, dots or stems, with optional horizontal reference lines.
#[derive(Clone, Debug, PartialEq)]
pub struct LineChart {
    /// Title.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// The data.
    pub series: Vec<Series>,
    /// Dashed horizontal lines `(y, label)` (confidence bands, zero).
    pub hlines: Vec<(f64, String)>,
    /// Size in pixels.
    pub size: (u32, u32),
}

const PALETTE: [(u8, u8, u8); 8] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
];

impl LineChart {
    /// An empty chart (560 × 300 px).
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            hlines: Vec::new(),
            size: (560, 300),
        }
    }
    /// Adds a series.
    pub fn series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }
    /// Adds a dashed horizontal line.
    pub fn hline(mut self, y: f64, label: impl Into<String>) -> Self {
        self.hlines.push((y, label.into()));
        self
    }
    /// Sets the size in pixels.
    pub fn size(mut self, w: u32, h: u32) -> Self {
        self.size = (w, h);
        self
    }

    fn ranges(&self) -> Option<((f64, f64), (f64, f64))> {
        let mut xr = (f64::INFINITY, f64::NEG_INFINITY);
        let mut yr = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &self.series {
            for &(x, y) in &s.points {
                if x.is_finite() && y.is_finite() {
                    xr = (xr.0.min(x), xr.1.max(x));
                    yr = (yr.0.min(y), yr.1.max(y));
                }
            }
            if s.style == SeriesStyle::Stems {
                yr = (yr.0.min(0.0), yr.1.max(0.0));
            }
        }
        for &(y, _) in &self.hlines {
            if y.is_finite() {
                yr = (yr.0.min(y), yr.1.max(y));
            }
        }
        if !(xr.0 <= xr.1 && yr.0 <= yr.1) {
            return None;
        }
        let pad = |(a, b): (f64, f64)| {
            let w = (b - a).abs();
            let p = if w > 0.0 {
                0.05 * w
            } else {
                a.abs().max(1.0) * 0.05
            };
            (a - p, b + p)
        };
        Some((pad(xr), pad(yr)))
    }
}

/// A tick label: three decimals, or three significant digits in scientific notation when the
/// ticks are closer than 0.001 or the values larger than 10⁴ (three decimals would print equal
/// labels or long numbers).
fn tick_label(v: f64, step: f64) -> String {
    if v != 0.0 && (step.abs() < 1e-3 || v.abs() >= 1e4) {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}

fn plot_err(title: &str) -> impl Fn(String) -> ReportError + '_ {
    move |reason| ReportError::Plot {
        title: title.to_string(),
        reason,
    }
}

impl Chart for LineChart {
    fn title(&self) -> &str {
        &self.title
    }
    fn render_svg(&self) -> Result<String, ReportError> {
        use plotters::prelude::*;
        let err = plot_err(&self.title);
        let ((x0, x1), (y0, y1)) = self
            .ranges()
            .ok_or_else(|| err("no finite points".into()))?;
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, ("sans-serif", 16))
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(62)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(e.to_string()))?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .x_labels(8)
                .y_labels(6)
                .y_label_formatter(&|v| tick_label(*v, (y1 - y0) / 6.0))
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(|e| err(e.to_string()))?;
            for (i, &(y, _)) in self.hlines.iter().enumerate() {
                let style = ShapeStyle::from(&BLACK.mix(0.5)).stroke_width(1);
                let n = 60;
                let segs = (0..n).step_by(2).map(move |j| {
                    let a = x0 + (x1 - x0) * j as f64 / n as f64;
                    let b = x0 + (x1 - x0) * (j + 1) as f64 / n as f64;
                    PathElement::new(vec![(a, y), (b, y)], style)
                });
                let _ = i;
                chart.draw_series(segs).map_err(|e| err(e.to_string()))?;
            }
            for (i, s) in self.series.iter().enumerate() {
                let (r, g, b) = PALETTE[i % PALETTE.len()];
                let color = RGBColor(r, g, b);
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|(x, y)| x.is_finite() && y.is_finite())
                    .collect();
                let anno = match s.style {
                    SeriesStyle::Line => chart
                        .draw_series(
                            finite_runs(&s.points)
                                .into_iter()
                                .map(|run| PathElement::new(run, color.stroke_width(1))),
                        )
                        .map_err(|e| err(e.to_string()))?,
                    SeriesStyle::Points => chart
                        .draw_series(pts.into_iter().map(|p| Circle::new(p, 2, color.filled())))
                        .map_err(|e| err(e.to_string()))?,
                    SeriesStyle::Stems => chart
                        .draw_series(pts.into_iter().map(|(x, y)| {
                            PathElement::new(vec![(x, 0.0), (x, y)], color.stroke_width(2))
                        }))
                        .map_err(|e| err(e.to_string()))?,
                };
                anno.label(&s.name).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
            }
            if !self.series.is_empty() {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK.mix(0.4))
                    .label_font(("sans-serif", 12))
                    .draw()
                    .map_err(|e| err(e.to_string()))?;
            }
            root.present().map_err(|e| err(e.to_string()))?;
        }
        Ok(buf)
    }
}

/// A map of values over a 2-D grid of cells (e.g. error over the floor), colour from white (0)
/// to dark red (the largest value); cells without a value are left grey.
#[derive(Clone, Debug, PartialEq)]
pub struct Heatmap {
    /// Title.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// Cell edges along x (`nx + 1`, increasing).
    pub x_edges: Vec<f64>,
    /// Cell edges along y (`ny + 1`, increasing).
    pub y_edges: Vec<f64>,
    /// Values `[iy][ix]`; `None` for an empty cell.
    pub values: Vec<Vec<Option<f64>>>,
    /// Size in pixels.
    pub size: (u32, u32),
}

impl Heatmap {
    /// The largest finite value (0 when there is none): the dark red end of the colour scale.
    pub fn max_value(&self) -> f64 {
        self.values
            .iter()
            .flatten()
            .flatten()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
    }

    /// Checks the grid; returns `(nx, ny)`.
    fn grid(&self) -> Result<(usize, usize), ReportError> {
        let err = plot_err(&self.title);
        let (nx, ny) = (
            self.x_edges.len().saturating_sub(1),
            self.y_edges.len().saturating_sub(1),
        );
        if nx == 0 || ny == 0 || self.values.len() != ny {
            return Err(err("empty grid".into()));
        }
        if !(self.x_edges[nx] > self.x_edges[0] && self.y_edges[ny] > self.y_edges[0]) {
            return Err(err("degenerate extent".into()));
        }
        Ok((nx, ny))
    }

    /// Draws the map on `area` with the colour scale `0…vmax` under `caption`.
    fn draw_on<DB: plotters::prelude::DrawingBackend>(
        &self,
        area: &plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
        caption: String,
        vmax: f64,
    ) -> Result<(), ReportError> {
        use plotters::prelude::*;
        let err = plot_err(&self.title);
        let (nx, ny) = self.grid()?;
        let (x0, x1) = (self.x_edges[0], self.x_edges[nx]);
        let (y0, y1) = (self.y_edges[0], self.y_edges[ny]);
        let mut chart = ChartBuilder::on(area)
            .caption(caption, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .draw()
            .map_err(|e| err(e.to_string()))?;
        let mut cells = Vec::new();
        for (iy, row) in self.values.iter().enumerate() {
            for (ix, v) in row.iter().enumerate().take(nx) {
                cells.push(Rectangle::new(
                    [
                        (self.x_edges[ix], self.y_edges[iy]),
                        (self.x_edges[ix + 1], self.y_edges[iy + 1]),
                    ],
                    heat_color(*v, vmax).filled(),
                ));
            }
        }
        chart.draw_series(cells).map_err(|e| err(e.to_string()))?;
        Ok(())
    }
}

/// The colour of a cell: white at 0 to dark red at `vmax`, grey without a value.
fn heat_color(v: Option<f64>, vmax: f64) -> plotters::style::RGBColor {
    use plotters::style::{RGBColor, WHITE};
    match v {
        Some(v) if v.is_finite() && vmax > 0.0 => {
            let a = (v / vmax).clamp(0.0, 1.0);
            RGBColor(
                255 - (a * 100.0) as u8,
                255 - (a * 235.0) as u8,
                255 - (a * 235.0) as u8,
            )
        }
        Some(_) => WHITE,
        None => RGBColor(225, 225, 225),
    }
}

impl Chart for Heatmap {
    fn title(&self) -> &str {
        &self.title
    }
    fn render_svg(&self) -> Result<String, ReportError> {
        use plotters::prelude::*;
        let err = plot_err(&self.title);
        self.grid()?;
        let vmax = self.max_value();
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
            self.draw_on(&root, format!("{} (max {:.4})", self.title, vmax), vmax)?;
            root.present().map_err(|e| err(e.to_string()))?;
        }
        Ok(buf)
    }
}

/// Heatmaps side by side in one figure on one colour scale — white at 0, dark red at the
/// largest value over all panels — with a colour bar below, so that equal colours mean equal
/// values in every panel (e.g. a model's error over the floor before and after a change).
///
/// Each panel keeps its own title, axis labels and grid; its `size` is ignored: the panels
/// share the figure's width evenly.
#[derive(Clone, Debug, PartialEq)]
pub struct HeatmapPanels {
    /// Title of the figure (also its caption).
    pub title: String,
    /// The panels, left to right.
    pub panels: Vec<Heatmap>,
    /// Label of the colour bar (what the colour means, with its unit).
    pub scale_label: String,
    /// Size of the whole figure in pixels.
    pub size: (u32, u32),
}

impl HeatmapPanels {
    /// Panels of `size_each` pixels side by side (plus the title and the colour bar).
    pub fn new(
        title: impl Into<String>,
        scale_label: impl Into<String>,
        panels: Vec<Heatmap>,
        size_each: (u32, u32),
    ) -> Self {
        let n = panels.len().max(1) as u32;
        Self {
            title: title.into(),
            scale_label: scale_label.into(),
            panels,
            size: (size_each.0 * n, size_each.1 + COLOUR_BAR_HEIGHT + 30),
        }
    }

    /// The top of the shared colour scale: the largest value over all panels.
    pub fn max_value(&self) -> f64 {
        self.panels
            .iter()
            .map(Heatmap::max_value)
            .fold(0.0, f64::max)
    }
}

/// Height of the colour bar of [`HeatmapPanels`] in pixels.
const COLOUR_BAR_HEIGHT: u32 = 70;

impl Chart for HeatmapPanels {
    fn title(&self) -> &str {
        &self.title
    }
    fn render_svg(&self) -> Result<String, ReportError> {
        use plotters::prelude::*;
        let err = plot_err(&self.title);
        if self.panels.is_empty() {
            return Err(err("no panels".into()));
        }
        for p in &self.panels {
            p.grid()?;
        }
        let vmax = self.max_value();
        let mut buf = String::new();
        {
            let root = SVGBackend::with_string(&mut buf, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
            let body = root
                .titled(
                    &format!("{} (shared scale, max {:.4})", self.title, vmax),
                    ("sans-serif", 17),
                )
                .map_err(|e| err(e.to_string()))?;
            let h = body.dim_in_pixel().1;
            let (maps, bar) = body.split_vertically(h.saturating_sub(COLOUR_BAR_HEIGHT));
            for (p, area) in self
                .panels
                .iter()
                .zip(maps.split_evenly((1, self.panels.len())))
            {
                p.draw_on(
                    &area,
                    format!("{} (max {:.4})", p.title, p.max_value()),
                    vmax,
                )?;
            }
            // colour bar: the scale from 0 to the shared maximum
            let top = if vmax > 0.0 { vmax } else { 1.0 };
            let w = bar.dim_in_pixel().0;
            let bar = bar.margin(4, 0, w / 6, w / 6);
            let mut cb = ChartBuilder::on(&bar)
                .x_label_area_size(40)
                .build_cartesian_2d(0.0..top, 0.0..1.0)
                .map_err(|e| err(e.to_string()))?;
            cb.configure_mesh()
                .disable_mesh()
                .disable_y_axis()
                .x_desc(&self.scale_label)
                .x_labels(6)
                .x_label_formatter(&|v| tick_label(*v, top / 6.0))
                .label_style(("sans-serif", 12))
                .axis_desc_style(("sans-serif", 12))
                .draw()
                .map_err(|e| err(e.to_string()))?;
            let n = 60;
            cb.draw_series((0..n).map(|i| {
                let (a, b) = (top * i as f64 / n as f64, top * (i + 1) as f64 / n as f64);
                Rectangle::new(
                    [(a, 0.0), (b, 1.0)],
                    heat_color(Some(0.5 * (a + b)), vmax).filled(),
                )
            }))
            .map_err(|e| err(e.to_string()))?;
            root.present().map_err(|e| err(e.to_string()))?;
        }
        Ok(buf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn html_escapes_text_and_lists_sections() {
        let mut r = Report::new("a <b> & c");
        r.section("one")
            .text("x < y")
            .table(Table::new(["k", "v"]).caption("cap").row(["<script>", "1"]));
        r.section("two").note("careful");
        let h = r.to_html();
        assert!(h.contains("a &lt;b&gt; &amp; c"));
        assert!(h.contains("&lt;script&gt;"));
        assert!(!h.contains("<script>"));
        assert!(h.contains("href=\"#s1\">two</a>"));
        assert!(h.contains("class=\"note\">careful"));
    }

    #[test]
    fn text_table_aligns_columns() {
        let t = Table::new(["state", "RMSE"])
            .row(["x", "1.5"])
            .row(["omega", "10.25"]);
        let s = t.to_text();
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[1].len(), lines[2].len());
        assert!(lines[2].starts_with("omega"));
    }

    #[test]
    fn charts_render_svg_or_say_why_not() {
        let chart = LineChart::new("c", "x", "y")
            .series(Series::line("a", vec![(0.0, 1.0), (1.0, 2.0)]))
            .series(Series::stems("b", vec![(0.5, -1.0)]))
            .hline(0.5, "band");
        let mut r = Report::new("t");
        r.section("s").chart(&chart);
        let empty = LineChart::new("empty", "x", "y");
        r.section("e").chart(&empty);
        let h = r.to_html();
        // either the SVG is there or a note explains its absence; never both missing
        assert!(h.contains("<svg") || h.contains("figure not drawn"));
        assert!(
            h.contains("figure not drawn: drawing the chart &quot;empty&quot;: no finite points")
        );
    }

    #[test]
    fn lines_break_at_non_finite_points() {
        let runs = finite_runs(&[
            (0.0, 1.0),
            (1.0, 2.0),
            (f64::NAN, f64::NAN),
            (2.0, 0.5),
            (3.0, f64::INFINITY),
            (f64::NAN, 0.0),
        ]);
        assert_eq!(runs, vec![vec![(0.0, 1.0), (1.0, 2.0)], vec![(2.0, 0.5)]]);
        let svg = LineChart::new("c", "x", "y")
            .series(Series::line(
                "a",
                vec![
                    (0.0, 1.0),
                    (1.0, 2.0),
                    (f64::NAN, f64::NAN),
                    (2.0, 0.0),
                    (3.0, 1.0),
                ],
            ))
            .render_svg()
            .unwrap();
        // two data runs and the legend swatch, all in the first colour
        let blue = svg
            .split("<polyline")
            .filter(|p| p.split('>').next().unwrap().contains("#1F77B4"))
            .count();
        assert_eq!(blue, 3, "{svg}");
    }

    #[test]
    fn heatmap_panels_share_one_colour_scale() {
        let map = |title: &str, v: f64| Heatmap {
            title: title.into(),
            x_label: "x".into(),
            y_label: "y".into(),
            x_edges: vec![0.0, 1.0, 2.0],
            y_edges: vec![0.0, 1.0],
            values: vec![vec![Some(v), None]],
            size: (300, 300),
        };
        let (a, b) = (map("a", 1.0), map("b", 2.0));
        // alone, each map's largest value is dark red
        let dark = "#9B1414";
        assert!(a.render_svg().unwrap().contains(dark));
        // together, 1 is half way (and 2 dark red), whichever panel it is in
        let half = format!(
            "#{:02X}{:02X}{:02X}",
            255 - 50,
            255 - (0.5f64 * 235.0) as u8,
            255 - (0.5f64 * 235.0) as u8
        );
        let p = HeatmapPanels::new("both", "error", vec![a.clone(), b.clone()], (300, 300));
        assert_eq!(p.max_value(), 2.0);
        let svg = p.render_svg().unwrap();
        assert!(svg.contains("both (shared scale, max 2.0000)"));
        assert!(svg.contains("a (max 1.0000)") && svg.contains("b (max 2.0000)"));
        let cell = |svg: &str, colour: &str| {
            svg.split("<rect")
                .filter(|r| r.split('>').next().unwrap().contains(colour))
                .count()
        };
        assert_eq!(cell(&svg, &half), 1, "the cell of 1 in panel a");
        assert!(cell(&svg, dark) >= 1);
        // an empty grid is refused with the figure's name
        let e = HeatmapPanels::new("none", "error", vec![], (300, 300))
            .render_svg()
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"none\": no panels"), "{e}");
    }

    #[test]
    fn tick_labels_stay_distinct_for_small_and_large_values() {
        // ticks 0.0002 apart: three decimals would print 0.001 three times
        let small: Vec<String> = [0.0008, 0.001, 0.0012]
            .iter()
            .map(|&v| tick_label(v, 2e-4))
            .collect();
        assert_eq!(small, ["8.00e-4", "1.00e-3", "1.20e-3"]);
        assert_eq!(tick_label(0.25, 0.05), "0.250");
        assert_eq!(tick_label(0.0, 2e-4), "0.000");
        assert_eq!(tick_label(25000.0, 5000.0), "2.50e4");
    }
}
