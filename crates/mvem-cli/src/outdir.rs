//! Report directories: check an `--out DIR` before computing, render figures to SVG and PNG,
//! and write all files of a report atomically (each file via a temporary file and a rename)
//! once everything has been computed and rendered.

use crate::common;
use crate::plot::{self, Figure};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Refuse an `--out` path that exists and is not a directory (before any computation).
pub fn check(dir: &Path) -> Result<()> {
    if dir.as_os_str().is_empty() {
        return Err(common::usage("--out: empty directory name"));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(common::usage(format!(
            "--out {}: exists and is not a directory",
            dir.display()
        )));
    }
    Ok(())
}

/// Files of a report, collected in memory and written together by [`Files::write`].
#[derive(Default)]
pub struct Files(Vec<(String, Vec<u8>)>);

impl Files {
    /// Add a file `name` with `bytes`.
    pub fn add(&mut self, name: impl Into<String>, bytes: impl Into<Vec<u8>>) {
        self.0.push((name.into(), bytes.into()));
    }

    /// Add `STEM.svg` and `STEM.png` of a figure (the PNG at the best compression).
    pub fn figure(&mut self, stem: &str, fig: &Figure) -> Result<()> {
        self.add(format!("{stem}.svg"), plot::render(fig, plot::Format::Svg)?);
        let png = plot::render(fig, plot::Format::Png)?;
        self.add(format!("{stem}.png"), recompress_png(&png)?);
        Ok(())
    }

    /// Create `dir` if missing and write every file atomically; returns the paths written.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir)
            .map_err(|e| common::usage(format!("--out {}: {e}", dir.display())))?;
        let mut written = Vec::with_capacity(self.0.len());
        for (name, bytes) in &self.0 {
            let p = dir.join(name);
            mvem::io::output::write_atomic(&p, bytes)
                .with_context(|| format!("cannot write {}", p.display()))?;
            written.push(p);
        }
        Ok(written)
    }
}

/// "Wrote a, b, c" for the end of a command's output.
pub fn wrote(paths: &[PathBuf]) -> String {
    format!(
        "Wrote {}",
        paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// The same image re-encoded at the best deflate level: plotters' encoder writes at the fastest
/// level, about three times larger for line figures.
pub fn recompress_png(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut reader = png::Decoder::new(bytes)
        .read_info()
        .context("decoding the rendered PNG")?;
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .context("decoding the rendered PNG")?;
    let mut out = Vec::with_capacity(bytes.len() / 2);
    {
        let mut enc = png::Encoder::new(&mut out, info.width, info.height);
        enc.set_color(info.color_type);
        enc.set_depth(info.bit_depth);
        enc.set_compression(png::Compression::Best);
        enc.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
        let mut w = enc.write_header().context("encoding PNG")?;
        w.write_image_data(&buf[..info.buffer_size()])
            .context("encoding PNG")?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::{Panel, Series};

    #[test]
    fn recompressed_png_has_the_same_pixels_and_is_smaller() {
        let t: Vec<f64> = (0..400).map(|i| i as f64 * 0.01).collect();
        let y: Vec<f64> = t.iter().map(|v| (5.0 * v).sin()).collect();
        let mut f = Figure::new(1);
        f.panels
            .push(Panel::new("t [s]", "y [-]").with(Series::line("y", &t, &y, 0)));
        let png = plot::render(&f, plot::Format::Png).unwrap();
        let small = recompress_png(&png).unwrap();
        assert!(small.len() < png.len(), "{} vs {}", small.len(), png.len());
        let pixels = |b: &[u8]| {
            let mut r = png::Decoder::new(b).read_info().unwrap();
            let mut buf = vec![0; r.output_buffer_size()];
            let i = r.next_frame(&mut buf).unwrap();
            buf.truncate(i.buffer_size());
            (i.width, i.height, buf)
        };
        assert_eq!(pixels(&png), pixels(&small));
    }
}
