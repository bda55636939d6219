//! The report's plots, as SVG text (plotters): bars of category shares, histograms of
//! continuous values, scatter plots. Each plot shows one series per dataset (or variant), as
//! shares so datasets of different sizes compare. Axis text needs a font ([`crate::font`]);
//! without one the plots are drawn without it (the report's captions say what they show).

use plotters::prelude::*;

const W: u32 = 560;
const H: u32 = 300;

/// A named series of values.
pub type Series<'a> = (&'a str, Vec<f64>);

fn colour(i: usize) -> RGBColor {
    const C: [RGBColor; 6] = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
    ];
    C[i % C.len()]
}

fn short(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 || v == v.round() {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

type Res = anyhow::Result<String>;

fn fail<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("cannot draw a plot: {e}")
}

/// Shares of `categories` per series (each series: a count per category), grouped bars, with
/// an optional expected share per category drawn as black ticks.
pub fn bars(
    x_label: &str,
    categories: &[String],
    series: &[Series],
    expected: Option<&[f64]>,
) -> Res {
    let text = crate::font::available();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(fail)?;
        let shares: Vec<Vec<f64>> = series
            .iter()
            .map(|(_, c)| {
                let n: f64 = c.iter().sum::<f64>().max(1e-12);
                c.iter().map(|v| v / n).collect()
            })
            .collect();
        let top = shares
            .iter()
            .flatten()
            .chain(expected.unwrap_or(&[]))
            .fold(0.0f64, |a, &b| a.max(b))
            .max(1e-3)
            * 1.15;
        let k = categories.len().max(1);
        let mut b = builder(&root, text.then_some(if k > 8 { 70 } else { 35 }));
        let mut chart = b
            .build_cartesian_2d(0f64..k as f64, 0f64..top)
            .map_err(fail)?;
        let cats = categories.to_vec();
        let fmt = move |v: &f64| {
            let i = (v - 0.5).round();
            if (v - 0.5 - i).abs() < 1e-6 && i >= 0.0 {
                cats.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        };
        let mut mesh = chart.configure_mesh();
        mesh.disable_x_mesh();
        if text {
            mesh.x_desc(x_label)
                .y_desc("share")
                .x_labels(k * 2 + 1)
                .x_label_formatter(&fmt)
                .y_label_formatter(&|v| short(*v))
                .label_style(("sans-serif", 12));
            if k > 8 {
                mesh.x_label_style(
                    ("sans-serif", 11)
                        .into_font()
                        .transform(FontTransform::Rotate90),
                );
            }
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw().map_err(fail)?;
        let m = series.len().max(1) as f64;
        for (s, sh) in shares.iter().enumerate() {
            let c = colour(s);
            chart
                .draw_series(sh.iter().enumerate().map(|(i, &v)| {
                    let x0 = i as f64 + 0.1 + 0.8 * s as f64 / m;
                    Rectangle::new([(x0, 0.0), (x0 + 0.8 / m, v)], c.filled())
                }))
                .map_err(fail)?;
        }
        if let Some(e) = expected {
            chart
                .draw_series(e.iter().enumerate().map(|(i, &v)| {
                    PathElement::new(
                        vec![(i as f64 + 0.05, v), (i as f64 + 0.95, v)],
                        BLACK.stroke_width(2),
                    )
                }))
                .map_err(fail)?;
        }
        finish(&root, text.then_some(series))?;
    }
    Ok(svg)
}

/// A chart on `root` with the plots' margin and, for plots with text, label areas
/// (`x_labels` pixels under the x axis).
fn builder<'a, 'b, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, plotters::coord::Shift>,
    x_labels: Option<u32>,
) -> ChartBuilder<'a, 'b, DB> {
    let mut b = ChartBuilder::on(root);
    b.margin(10);
    if let Some(x) = x_labels {
        b.x_label_area_size(x).y_label_area_size(45);
    }
    b
}

/// The legend of `series` (when given: plots with text), then the drawing finished.
fn finish<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    series: Option<&[Series]>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    if let Some(series) = series {
        legend(root, series)?;
    }
    root.present().map_err(fail)
}

fn legend<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    series: &[Series],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    for (i, (name, _)) in series.iter().enumerate() {
        let y = 14 + 16 * i as i32;
        root.draw(&Rectangle::new(
            [(W as i32 - 170, y - 5), (W as i32 - 160, y + 5)],
            colour(i).filled(),
        ))
        .map_err(fail)?;
        root.draw_text(
            name,
            &("sans-serif", 12).into_font().color(&BLACK),
            (W as i32 - 155, y - 6),
        )
        .map_err(fail)?;
    }
    Ok(())
}

/// Histograms (shares per bin) of each series over a common range, with an optional
/// vertical marker (value, label) such as the 200-px rule. `log_x` bins log10 of the values.
pub fn histogram(x_label: &str, series: &[Series], marker: Option<f64>, log_x: bool) -> Res {
    let text = crate::font::available();
    let tf = |v: f64| if log_x { v.max(1e-9).log10() } else { v };
    let vals = || {
        series
            .iter()
            .flat_map(|s| s.1.iter().copied())
            .filter(|v| v.is_finite() && (!log_x || *v > 0.0))
            .map(tf)
    };
    let (mut lo, mut hi) = vals().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if let Some(m) = marker {
        lo = lo.min(tf(m));
        hi = hi.max(tf(m));
    }
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        (lo, hi) = (lo - 0.5, hi + 0.5);
    }
    let bins = 30usize;
    let width = (hi - lo) / bins as f64;
    let shares: Vec<Vec<f64>> = series
        .iter()
        .map(|(_, v)| {
            let mut h = vec![0.0; bins];
            let mut n = 0.0;
            for x in v
                .iter()
                .copied()
                .filter(|v| v.is_finite() && (!log_x || *v > 0.0))
            {
                let b = (((tf(x) - lo) / width) as usize).min(bins - 1);
                h[b] += 1.0;
                n += 1.0;
            }
            h.iter().map(|c| c / f64::max(n, 1.0)).collect()
        })
        .collect();
    let top = shares
        .iter()
        .flatten()
        .fold(0.0f64, |a, &b| a.max(b))
        .max(1e-3)
        * 1.15;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(fail)?;
        let mut b = builder(&root, text.then_some(35));
        let mut chart = b.build_cartesian_2d(lo..hi, 0f64..top).map_err(fail)?;
        let mut mesh = chart.configure_mesh();
        if text {
            let xf = move |v: &f64| short(if log_x { 10f64.powf(*v) } else { *v });
            mesh.x_desc(if log_x {
                format!("{x_label} (log scale)")
            } else {
                x_label.to_string()
            })
            .y_desc("share")
            .x_label_formatter(&xf)
            .y_label_formatter(&|v| short(*v))
            .label_style(("sans-serif", 12));
            mesh.draw().map_err(fail)?;
        } else {
            mesh.x_labels(0).y_labels(0).draw().map_err(fail)?;
        }
        for (s, sh) in shares.iter().enumerate() {
            let c = colour(s);
            let mut pts = Vec::with_capacity(2 * bins + 2);
            pts.push((lo, 0.0));
            for (i, &v) in sh.iter().enumerate() {
                pts.push((lo + i as f64 * width, v));
                pts.push((lo + (i + 1) as f64 * width, v));
            }
            pts.push((hi, 0.0));
            chart
                .draw_series(std::iter::once(Polygon::new(pts.clone(), c.mix(0.25))))
                .map_err(fail)?;
            chart
                .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                .map_err(fail)?;
        }
        if let Some(m) = marker {
            let x = tf(m);
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x, 0.0), (x, top)],
                    RED.stroke_width(2),
                )))
                .map_err(fail)?;
        }
        finish(&root, text.then_some(series))?;
    }
    Ok(svg)
}

/// Points `(x, y)` per series (at most 4,000 drawn per series, evenly strided).
pub fn scatter(x_label: &str, y_label: &str, series: &[(&str, Vec<(f64, f64)>)]) -> Res {
    let text = crate::font::available();
    let all = || series.iter().flat_map(|s| s.1.iter().copied());
    let (mut x0, mut x1, mut y0, mut y1) =
        all().filter(|p| p.0.is_finite() && p.1.is_finite()).fold(
            (
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ),
            |(a, b, c, d), (x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
        );
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    let pad = |a: f64, b: f64| {
        let p = ((b - a) * 0.05).max(1e-3);
        (a - p, b + p)
    };
    (x0, x1) = pad(x0, x1);
    (y0, y1) = pad(y0, y1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(fail)?;
        let mut b = builder(&root, text.then_some(35));
        let mut chart = b.build_cartesian_2d(x0..x1, y0..y1).map_err(fail)?;
        let mut mesh = chart.configure_mesh();
        if text {
            mesh.x_desc(x_label)
                .y_desc(y_label)
                .x_label_formatter(&|v| short(*v))
                .y_label_formatter(&|v| short(*v))
                .label_style(("sans-serif", 12));
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw().map_err(fail)?;
        for (s, (_, pts)) in series.iter().enumerate() {
            let c = colour(s);
            let step = (pts.len() / 4000).max(1);
            chart
                .draw_series(
                    pts.iter()
                        .step_by(step)
                        .map(|&p| Circle::new(p, 2, c.mix(0.6).filled())),
                )
                .map_err(fail)?;
        }
        let names: Vec<Series> = series.iter().map(|(n, _)| (*n, Vec::new())).collect();
        finish(&root, text.then_some(&names))?;
    }
    Ok(svg)
}
