//! The error-against-time plot (log-log, one curve per sampling mode) as SVG and PNG.
//!
//! Text needs a font registered with plotters (the command line's `font::available`); without
//! one the caller passes `text: false`, the plot is drawn without text and the user is told so.

use std::path::Path;

use anyhow::Context;
use plotters::prelude::*;

/// One point of a curve: x = seconds, y = relative error.
pub type Curve = (String, Vec<(f64, f64)>);

const W: u32 = 900;
const H: u32 = 600;

/// Write `stem.svg` and `stem.png`, with text (axes, legend) if `text` (a font is
/// registered). Returns `text`.
pub fn write(
    stem: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
    text: bool,
) -> anyhow::Result<bool> {
    let svg = stem.with_extension("svg");
    {
        let root = SVGBackend::new(&svg, (W, H)).into_drawing_area();
        draw(&root, title, x_label, y_label, curves, text)?;
        root.present()
            .map_err(|e| anyhow::anyhow!("cannot write `{}`: {e}", svg.display()))?;
    }
    let png = stem.with_extension("png");
    let mut buf = vec![255u8; (W * H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area();
        draw(&root, title, x_label, y_label, curves, text)?;
        root.present()
            .map_err(|e| anyhow::anyhow!("cannot draw the PNG plot: {e}"))?;
    }
    let img = image::RgbImage::from_raw(W, H, buf).context("plot buffer has the wrong size")?;
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .context("cannot encode the PNG plot")?;
    clevrtex_dataset::atomic::write(&png, &bytes).with_context(|| {
        format!(
            "cannot write `{}`\nhint: check that the folder is writable",
            png.display()
        )
    })?;
    Ok(text)
}

/// A tick label with about two significant digits: `0.034`, `1.5`, `120`.
fn short(v: f64) -> String {
    let a = v.abs();
    if a >= 10.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else if a >= 0.1 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (1e-3, 1.0);
    }
    // Half a decade of room on each side keeps end points off the frame.
    (lo / 1.5, hi * 1.5)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
    text: bool,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("cannot draw the plot: {e}");
    root.fill(&WHITE).map_err(err)?;
    let (x0, x1) = bounds(curves.iter().flat_map(|c| c.1.iter().map(|p| p.0)));
    let (y0, y1) = bounds(curves.iter().flat_map(|c| c.1.iter().map(|p| p.1)));
    let mut builder = ChartBuilder::on(root);
    builder.margin(20);
    if text {
        builder
            .caption(title, ("sans-serif", 22))
            .x_label_area_size(45)
            .y_label_area_size(70);
    }
    let mut chart = builder
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(err)?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc(x_label)
            .y_desc(y_label)
            .label_style(("sans-serif", 14))
            .x_labels(8)
            .y_labels(8)
            .x_label_formatter(&|v| short(*v))
            .y_label_formatter(&|v| short(*v));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(err)?;
    for (i, (name, points)) in curves.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let mut pts: Vec<(f64, f64)> = points
            .iter()
            .copied()
            .filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite())
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let series = chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
            .map_err(err)?;
        if text {
            series.label(name.as_str()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        }
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(err)?;
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}
