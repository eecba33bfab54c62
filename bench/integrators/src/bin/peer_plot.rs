//! The work-precision figure of `bench/peer_precision.sh`: mvem and the CVODE peer, integration
//! time against the max scaled deviation from the reference, one point per tolerance.
//!
//! Run: `cargo run --release --manifest-path bench/integrators/Cargo.toml --bin peer_plot --
//! POINTS.csv OUT.png [NOTE]` with the CSV the script writes (`OUT=POINTS.csv`); NOTE (e.g. the
//! machine's load) goes under the title.

use anyhow::{anyhow, bail, Context, Result};
use plotters::prelude::*;
use plotters::style::FontStyle;

static FONT: &[u8] = include_bytes!("../../../../assets/DejaVuSans.ttf");

/// One row of the script's CSV: rtol, then (time [s], deviation) of mvem, the peer with its own
/// absolute tolerance, and the peer with mvem's.
struct Row {
    rtol: f64,
    series: [(f64, f64); 3],
}

fn read(path: &str) -> Result<Vec<Row>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {path}"))?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{path} line {}: not a number", i + 1))?;
        if v.len() != 7 || v.iter().any(|x| !x.is_finite() || *x <= 0.0) {
            bail!("{path} line {}: expected 7 positive numbers", i + 1);
        }
        rows.push(Row {
            rtol: v[0],
            series: [(v[1], v[2]), (v[3], v[4]), (v[5], v[6])],
        });
    }
    if rows.is_empty() {
        bail!("{path}: no points");
    }
    Ok(rows)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        bail!("usage: peer_plot POINTS.csv OUT.png [NOTE]");
    }
    let rows = read(&args[1])?;
    let note = args.get(3).cloned().unwrap_or_default();
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow!("cannot load the embedded DejaVuSans font"))?;
    let root = BitMapBackend::new(&args[2], (1000, 720)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
    let all = rows.iter().flat_map(|r| r.series.iter());
    let (t0, t1, d0, d1) = all.fold(
        (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64),
        |(a, b, c, d), &(t, dev)| (a.min(t), b.max(t), c.min(dev), d.max(dev)),
    );
    // whole decades (plotters places a log axis' ticks from the decade of its start)
    let (t0, t1) = (
        10f64.powf((t0 * 1e3).log10().floor()),
        10f64.powf((t1 * 1e3).log10().ceil()),
    );
    let (d0, d1) = (
        10f64.powf(d0.log10().floor()),
        10f64.powf(d1.log10().ceil()),
    );
    let caption = if note.is_empty() {
        "WHTC, 8 states: integration time vs accuracy".to_string()
    } else {
        format!("WHTC, 8 states: integration time vs accuracy ({note})")
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(55)
        .y_label_area_size(85)
        .build_cartesian_2d((t0..t1).log_scale(), (d0..d1).log_scale())
        .map_err(|e| anyhow!("{e:?}"))?;
    chart
        .configure_mesh()
        .x_desc("integration time [ms] (median over rounds of the min of each round)")
        .y_desc("max scaled deviation from the rtol 1e-10 reference [-]")
        .x_labels(30)
        .x_label_formatter(&|v| {
            // 1, 2 and 5 times a power of ten
            let m = v / 10f64.powf(v.log10().floor());
            if [1.0, 2.0, 5.0, 10.0]
                .iter()
                .any(|n| (m - n).abs() < 1e-6 * n)
            {
                format!("{v:.0}")
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(|e| anyhow!("{e:?}"))?;
    let names = [
        ("mvem (ROS34PW2, atol = rtol x scale)", RGBColor(0, 0, 0)),
        (
            "CVODE peer (BDF, atol = 1e-2 rtol x scale, its default)",
            RGBColor(214, 39, 40),
        ),
        (
            "CVODE peer (BDF, atol = rtol x scale, as mvem)",
            RGBColor(31, 119, 180),
        ),
    ];
    for (k, (name, c)) in names.iter().enumerate() {
        let c = *c;
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| (r.series[k].0 * 1e3, r.series[k].1))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
            .map_err(|e| anyhow!("{e:?}"))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(3)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))
            .map_err(|e| anyhow!("{e:?}"))?;
        // ring around each program's default tolerance (rtol 1e-6)
        for (r, p) in rows.iter().zip(&pts) {
            if (r.rtol - 1e-6).abs() < 1e-12 {
                chart
                    .draw_series(std::iter::once(Circle::new(*p, 9, c.stroke_width(2))))
                    .map_err(|e| anyhow!("{e:?}"))?;
            }
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|e| anyhow!("{e:?}"))?;
    root.present().map_err(|e| anyhow!("{e:?}"))?;
    let rtols: Vec<String> = rows.iter().map(|r| format!("{:e}", r.rtol)).collect();
    println!(
        "wrote {} ({} tolerances: {}; rings at rtol 1e-6)",
        args[2],
        rows.len(),
        rtols.join(" ")
    );
    Ok(())
}
