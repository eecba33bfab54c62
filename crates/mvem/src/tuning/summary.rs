//! What a loaded campaign holds and which tuning steps it supports, before any tuning: the
//! check a user runs on a campaign made elsewhere (`mvem campaign --data DIR`).
//!
//! The steps' data needs are the pipeline's ([`super::pipeline::tune`]): step 1 the stationary
//! points, step 2 a set with role `actuator`, steps 3 and 4 sets with role `dynamic` (VGT/EGR
//! steps for step 3, a fuel step for step 4), step 5 sets with role `static` (not the actuator
//! set); sets with role `validation` only serve `mvem validate`.

use super::data::{Campaign, DynamicData, Role, StepKind};
use super::pipeline::step_title;
use super::steps::STEP1_MIN_POINTS;
use serde::Serialize;

/// A campaign's summary ([`summarize`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CampaignSummary {
    /// The manifest's description.
    pub description: String,
    /// Number of stationary points.
    pub stationary_points: usize,
    /// Range of the stationary points' engine speed [r/min].
    pub n_e_rpm: [f64; 2],
    /// Range of their fuel [mg/cycle/cylinder].
    pub u_delta_mg: [f64; 2],
    /// Range of their torque \[Nm\].
    pub m_e_nm: [f64; 2],
    /// Whether the stationary file has `T_t` (optional: no step uses it).
    pub t_t: bool,
    /// The manifest's `[columns]` renames (mvem's name -> the files').
    pub renamed: super::data::ColumnNames,
    /// The manifest's `[units]` conversions (column -> unit).
    pub units: super::data::ColumnUnits,
    /// The dynamic sets in manifest order.
    pub datasets: Vec<SetSummary>,
    /// Steps 1-5: which sets each would use, or what is missing.
    pub steps: Vec<StepSupport>,
    /// What the user should check before tuning, one line each ([`sampling_warnings`], then
    /// the commands outside the parameter set's command ranges).
    pub warnings: Vec<String>,
}

/// One dynamic set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SetSummary {
    /// Name.
    pub name: String,
    /// What is stepped (`vgt-egr`, `fuel`, `actuator`).
    pub kind: StepKind,
    /// Roles.
    pub roles: Vec<Role>,
    /// Samples.
    pub samples: usize,
    /// Time span \[s\].
    pub duration_s: f64,
    /// The manifest's sample rate \[Hz\].
    pub sample_rate_hz: f64,
    /// The data's sample rate: 1 / the median time step \[Hz\] (0 for a single sample).
    pub measured_rate_hz: f64,
    /// Command steps: samples where u_egr, u_vgt or u_delta moves by more than
    /// [`STEP_THRESHOLD`] from the sample before.
    pub command_steps: usize,
    /// Whether the set has the measured actuator positions (u_egr_pos, u_vgt_pos).
    pub positions: bool,
}

/// Smallest command change counted as a step (% for u_egr and u_vgt, mg for u_delta).
pub const STEP_THRESHOLD: f64 = 0.1;

/// Relative difference between a set's declared sample rate (the manifest's `sample_rate_hz`)
/// and its measured one (1 / the median time step) beyond which [`sampling_warnings`] reports
/// it.
pub const RATE_TOLERANCE: f64 = 0.02;

/// A time step longer than this many median steps is a hole in the sampling
/// ([`sampling_warnings`]).
pub const GAP_FACTOR: f64 = 10.0;

/// `v` to 4 significant digits (for messages).
fn sig(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(3 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

/// Warnings on the dynamic sets' time bases, one line each: a measured sample rate that differs
/// from the manifest's by more than [`RATE_TOLERANCE`] (a factor of about 1000 means times
/// logged in ms and read as s: `t = "ms"` in `[units]`), and holes in the sampling (a step
/// longer than [`GAP_FACTOR`] median steps: the longest and how many). The tuning and
/// validation simulate across a hole with the commands held at their last sample (zero-order
/// hold), so a command change inside it is missed. Empty when every set is regular.
pub fn sampling_warnings(c: &Campaign) -> Vec<String> {
    let mut out = Vec::new();
    for (info, d) in c.manifest.datasets.iter().zip(&c.dynamic) {
        let dt = median_step(&d.t);
        if dt <= 0.0 {
            continue;
        }
        let measured = 1.0 / dt;
        let ratio = info.sample_rate_hz / measured;
        if (ratio - 1.0).abs() > RATE_TOLERANCE {
            let ms = (ratio / 1000.0 - 1.0).abs() < 0.05;
            out.push(format!(
                "set {} ({}): the manifest's sample_rate_hz = {} but its times are sampled at {} Hz \
                 (median step {} s), {}{}",
                info.name,
                info.file,
                info.sample_rate_hz,
                sig(measured),
                sig(dt),
                if ratio > 1.0 {
                    format!("{} times slower", sig(ratio))
                } else {
                    format!("{} times faster", sig(1.0 / ratio))
                },
                if ms {
                    ": times logged in ms are read as seconds unless the manifest's [units] \
                     says t = \"ms\" (docs/tuning-data.md)"
                } else {
                    ": check the manifest's rate and the time column's unit"
                }
            ));
        }
        let gaps: Vec<(usize, f64, f64)> = (d.t.windows(2).enumerate())
            .filter(|(_, w)| w[1] - w[0] > GAP_FACTOR * dt)
            .map(|(k, w)| (k, w[0], w[1]))
            .collect();
        if let Some(&(k, a, b)) = gaps
            .iter()
            .max_by(|x, y| (x.2 - x.1).total_cmp(&(y.2 - y.1)))
        {
            // the times in full (a clock that does not start at 0 needs every digit to find
            // them in the file) and the samples' numbers
            out.push(format!(
                "set {} ({}): irregular sampling: {} hole(s) longer than {GAP_FACTOR} median \
                 steps ({} s), the longest {} s from t = {} s to {} s (samples {} and {} of \
                 {}); tune and validate simulate across it with the commands held at their \
                 last sample",
                info.name,
                info.file,
                gaps.len(),
                sig(dt),
                sig(b - a),
                crate::numerics::Num(a),
                crate::numerics::Num(b),
                k + 1,
                k + 2,
                d.t.len()
            ));
        }
    }
    out
}

/// Whether the campaign supports a tuning step, with the sets it would use.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepSupport {
    /// Step 1-5.
    pub step: u8,
    /// What the step estimates.
    pub title: &'static str,
    /// Whether the data support it.
    pub supported: bool,
    /// The data it would use (stationary points or set names), or what is missing.
    pub uses: String,
}

fn range(v: impl Iterator<Item = f64>) -> [f64; 2] {
    v.fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], x| {
        [lo.min(x), hi.max(x)]
    })
}

/// The median (the upper one of an even count) of `v`, `None` when empty.
pub(crate) fn median(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// The median time step of `t` (0 for fewer than two samples).
pub(crate) fn median_step(t: &[f64]) -> f64 {
    median(t.windows(2).map(|w| w[1] - w[0]).collect()).unwrap_or(0.0)
}

/// Command steps of equally long channels: the samples where any of them moves by more than
/// [`STEP_THRESHOLD`] from the sample before.
pub(crate) fn steps_in(channels: &[&[f64]]) -> usize {
    let n = channels.iter().map(|u| u.len()).min().unwrap_or(0);
    (1..n)
        .filter(|&k| {
            channels
                .iter()
                .any(|u| (u[k] - u[k - 1]).abs() > STEP_THRESHOLD)
        })
        .count()
}

fn command_steps(d: &DynamicData) -> usize {
    let cmds: Vec<&[f64]> = ["u_egr", "u_vgt", "u_delta"]
        .iter()
        .filter_map(|c| d.get(c))
        .collect();
    steps_in(&cmds)
}

/// A kind or role by its manifest name (`vgt-egr`, `static`, ...).
pub(crate) fn manifest_name<T: Serialize>(v: &T) -> String {
    serde_json::to_value(v)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

/// Roles by their manifest names, comma separated.
pub(crate) fn roles_text(roles: &[Role]) -> String {
    roles
        .iter()
        .map(manifest_name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Summarize a loaded campaign (see the module documentation) for the published parameters'
/// command ranges ([`summarize_for`]).
pub fn summarize(c: &Campaign) -> CampaignSummary {
    summarize_for(
        c,
        &crate::params::Params::published().input_saturation,
        "the published parameters",
    )
}

/// Summarize a loaded campaign for the parameter set `set` names, whose input saturation is
/// `s`: its warnings are [`campaign_warnings`].
pub fn summarize_for(
    c: &Campaign,
    s: &crate::params::InputSaturation,
    set: &str,
) -> CampaignSummary {
    let st = &c.stationary;
    let m = &c.manifest;
    let datasets: Vec<SetSummary> = m
        .datasets
        .iter()
        .zip(&c.dynamic)
        .map(|(i, d)| {
            let dt = median_step(&d.t);
            SetSummary {
                name: i.name.clone(),
                kind: i.kind,
                roles: i.roles.clone(),
                samples: d.t.len(),
                duration_s: d.t.last().copied().unwrap_or(0.0)
                    - d.t.first().copied().unwrap_or(0.0),
                sample_rate_hz: i.sample_rate_hz,
                measured_rate_hz: if dt > 0.0 { 1.0 / dt } else { 0.0 },
                command_steps: command_steps(d),
                positions: d.get("u_egr_pos").is_some() && d.get("u_vgt_pos").is_some(),
            }
        })
        .collect();
    let names = |f: &dyn Fn(&SetSummary) -> bool| -> Vec<String> {
        datasets
            .iter()
            .filter(|s| f(s))
            .map(|s| s.name.clone())
            .collect()
    };
    let support = |step: u8, sets: Vec<String>, what: &str| StepSupport {
        step,
        title: step_title(step),
        supported: !sets.is_empty(),
        uses: if sets.is_empty() {
            format!("no {what}")
        } else {
            format!("sets {}", sets.join(", "))
        },
    };
    let has = |s: &SetSummary, r: Role| s.roles.contains(&r);
    let steps = vec![
        StepSupport {
            step: 1,
            title: step_title(1),
            supported: st.len() >= STEP1_MIN_POINTS,
            uses: if st.len() >= STEP1_MIN_POINTS {
                format!("{} stationary points", st.len())
            } else {
                format!(
                    "{} stationary points, at least {STEP1_MIN_POINTS} needed (the compressor \
                     efficiency's 7 parameters, eqs (58)-(65); the torque, EGR and turbine fits \
                     need 4-6)",
                    st.len()
                )
            },
        },
        // the pipeline takes the first actuator set
        support(
            2,
            names(&|s| has(s, Role::Actuator) && s.positions)
                .into_iter()
                .take(1)
                .collect(),
            "set with role \"actuator\"",
        ),
        support(
            3,
            names(&|s| has(s, Role::Dynamic) && s.kind == StepKind::VgtEgr),
            "VGT/EGR set with role \"dynamic\"",
        ),
        support(
            4,
            names(&|s| has(s, Role::Dynamic) && s.kind == StepKind::Fuel)
                .into_iter()
                .take(1)
                .collect(),
            "fuel-step set with role \"dynamic\"",
        ),
        support(
            5,
            names(&|s| has(s, Role::Static) && s.kind != StepKind::Actuator),
            "set with role \"static\"",
        ),
    ];
    CampaignSummary {
        description: m.description.clone(),
        stationary_points: st.len(),
        n_e_rpm: range(st.iter().map(|p| p.n_e)),
        u_delta_mg: range(st.iter().map(|p| p.u_delta)),
        m_e_nm: range(st.iter().map(|p| p.m_e)),
        t_t: st.iter().all(|p| p.t_t.is_finite()),
        renamed: m.columns.clone(),
        units: m.units.clone(),
        datasets,
        steps,
        warnings: campaign_warnings(c, s, set),
    }
}

/// What `mvem campaign`, `mvem tune` and `mvem validate` warn of in a loaded campaign before
/// they use it, one line each: its time bases ([`sampling_warnings`]), then its EGR and VGT
/// commands outside the command ranges `s` of the parameter set `set` names
/// ([`super::constants::commands_outside_ranges`]), which the model runs clamped.
pub fn campaign_warnings(
    c: &Campaign,
    s: &crate::params::InputSaturation,
    set: &str,
) -> Vec<String> {
    sampling_warnings(c)
        .into_iter()
        .chain(super::constants::commands_outside_ranges(c, s, set))
        .collect()
}

impl CampaignSummary {
    /// The summary as text (what `mvem campaign` prints).
    pub fn text(&self) -> String {
        let mut s = String::new();
        if !self.description.is_empty() {
            s.push_str(&format!("{}\n\n", self.description));
        }
        s.push_str(&format!(
            "Stationary points: {} (n_e {:.0}-{:.0} r/min, u_delta {:.1}-{:.1} mg/cycle, M_e {:.0}-{:.0} Nm{})\n",
            self.stationary_points,
            self.n_e_rpm[0],
            self.n_e_rpm[1],
            self.u_delta_mg[0],
            self.u_delta_mg[1],
            self.m_e_nm[0],
            self.m_e_nm[1],
            if self.t_t { "" } else { "; no T_t, which no step uses" }
        ));
        let pairs = |v: &std::collections::BTreeMap<String, String>, sep: &str| {
            v.iter()
                .map(|(a, b)| format!("{a}{sep}{b}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !self.renamed.is_empty() {
            s.push_str(&format!(
                "Columns renamed: {}\n",
                pairs(&self.renamed, " <- ")
            ));
        }
        if !self.units.is_empty() {
            s.push_str(&format!(
                "Units converted: {}\n",
                pairs(&self.units, " in ")
            ));
        }
        s.push_str(
            "\n| set | kind | roles | samples | duration [s] | rate [Hz] (measured) | command steps | positions |\n\
             |---|---|---|---:|---:|---:|---:|---|\n",
        );
        for d in &self.datasets {
            let kind = manifest_name(&d.kind);
            let roles = roles_text(&d.roles);
            s.push_str(&format!(
                "| {} | {} | {} | {} | {:.1} | {} ({:.4}) | {} | {} |\n",
                d.name,
                kind,
                roles,
                d.samples,
                d.duration_s,
                d.sample_rate_hz,
                d.measured_rate_hz,
                d.command_steps,
                if d.positions { "yes" } else { "no" }
            ));
        }
        s.push_str("\nTuning steps the data support (mvem tune --steps):\n");
        for st in &self.steps {
            s.push_str(&format!(
                "  {} step {} ({}): {}\n",
                if st.supported { "yes" } else { "NO " },
                st.step,
                st.title,
                st.uses
            ));
        }
        for w in &self.warnings {
            s.push_str(&format!("\nwarning: {w}"));
        }
        if !self.warnings.is_empty() {
            s.push('\n');
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;
    use crate::tuning::lab::{campaign, LabOptions};

    #[test]
    fn a_virtual_campaign_supports_every_step_and_its_sets_are_counted() {
        let opts = LabOptions {
            max_steps: Some(3),
            ..LabOptions::default()
        };
        let (c, _) = campaign(&Params::published(), &opts).unwrap();
        let s = summarize(&c);
        assert_eq!(s.stationary_points, c.stationary.len());
        assert!(s.steps.iter().all(|x| x.supported), "{:?}", s.steps);
        assert_eq!(s.datasets.len(), c.dynamic.len());
        for (d, set) in s.datasets.iter().zip(&c.dynamic) {
            assert_eq!(d.samples, set.t.len());
            // the manifest's rate is the data's
            assert!(
                (d.measured_rate_hz / d.sample_rate_hz - 1.0).abs() < 1e-6,
                "{d:?}"
            );
            // the steps the lab made are the steps counted
            let info = c
                .manifest
                .datasets
                .iter()
                .find(|i| i.name == d.name)
                .unwrap();
            assert_eq!(Some(d.command_steps), info.steps, "{d:?}");
        }
        assert!(s
            .text()
            .contains("yes step 5 (static parameters by cost (77)): sets "));
        // without the actuator and fuel sets: steps 2 and 4 not supported
        let mut c2 = c.clone();
        let keep: Vec<bool> = c2
            .manifest
            .datasets
            .iter()
            .map(|i| i.kind == StepKind::VgtEgr)
            .collect();
        let mut k = keep.iter();
        c2.manifest.datasets.retain(|_| *k.next().unwrap());
        let mut k = keep.iter();
        c2.dynamic.retain(|_| *k.next().unwrap());
        let s2 = summarize(&c2);
        let ok: Vec<bool> = s2.steps.iter().map(|x| x.supported).collect();
        assert_eq!(ok, [true, false, true, false, true]);
        assert!(s2.text().contains("NO  step 2"), "{}", s2.text());
        // the lab's actuator set commands the VGT down to 10 %, below the published parameters'
        // VGT range (the model runs it at 20 %): said, naming the set, the column and how far
        // (session 39); a parameter set whose VGT range reaches 10 % says nothing
        assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
        let w = &s.warnings[0];
        assert!(
            w.starts_with(
                "set J (J.csv): u_vgt leaves the VGT command range [20, 100] % of the published \
                 parameters (input_saturation.u_vgt) at "
            ),
            "{w}"
        );
        assert!(
            w.contains(" below, down to 10 % (10 points of % under 20 %))"),
            "{w}"
        );
        let mut wide = Params::published().input_saturation;
        wide.u_vgt = [10.0, 100.0];
        let s_wide = summarize_for(&c, &wide, "car.toml");
        assert!(s_wide.warnings.is_empty(), "{:?}", s_wide.warnings);
        // a narrower EGR range: the stationary points' and the sets' EGR commands above it
        wide.u_egr = [0.0, 30.0];
        let s_egr = summarize_for(&c, &wide, "car.toml");
        assert!(
            s_egr
                .warnings
                .iter()
                .any(|w| w.starts_with("the stationary points (")
                    && w.contains(
                        "u_egr leaves the EGR-valve command range [0, 30] % of car.toml"
                    )),
            "{:?}",
            s_egr.warnings
        );
        // QA finding: 3 or 5 stationary points were "yes step 1", which then failed
        let mut few = c.clone();
        few.stationary.truncate(STEP1_MIN_POINTS - 1);
        let s3 = summarize(&few);
        assert!(!s3.steps[0].supported);
        assert!(
            s3.steps[0]
                .uses
                .starts_with("6 stationary points, at least 7 needed"),
            "{}",
            s3.steps[0].uses
        );
    }

    /// QA findings: times logged in ms read as seconds (a 100 Hz set measured at 0.1 Hz) and a
    /// 5 s hole in a set went unreported; both are warnings naming the set, its file and what
    /// was measured.
    #[test]
    fn a_rate_unlike_the_manifest_and_holes_in_the_sampling_are_warned() {
        let opts = LabOptions {
            max_steps: Some(2),
            n_stationary: 13,
            sets: Some(vec!["I".into(), "J".into()]),
            ..LabOptions::default()
        };
        let (mut c, _) = campaign(&Params::published(), &opts).unwrap();
        assert!(sampling_warnings(&c).is_empty());
        let k = |c: &Campaign, n: &str| c.manifest.datasets.iter().position(|d| d.name == n);
        let (i, j) = (k(&c, "I").unwrap(), k(&c, "J").unwrap());
        for t in &mut c.dynamic[j].t {
            *t *= 1e3;
        }
        let n = c.dynamic[i].t.len();
        for t in &mut c.dynamic[i].t[n / 2..] {
            *t += 5.0;
        }
        let w = sampling_warnings(&c);
        assert_eq!(w.len(), 2, "{w:?}");
        let rate = w.iter().find(|m| m.starts_with("set J (J.csv)")).unwrap();
        assert!(
            rate.contains("sample_rate_hz = 100 but its times are sampled at 0.1 Hz")
                && rate.contains("1000 times slower")
                && rate.contains("t = \"ms\""),
            "{rate}"
        );
        let gap = w.iter().find(|m| m.starts_with("set I (I.csv)")).unwrap();
        assert!(
            gap.contains("irregular sampling: 1 hole(s)") && gap.contains("the longest 5.1 s"),
            "{gap}"
        );
        // QA (a test cell's clock from 10 h): the times were cut to 4 digits, "from t = 36010 s
        // to 36010 s"; now in full, with the samples' numbers
        for t in &mut c.dynamic[i].t {
            *t += 36000.0;
        }
        let w = sampling_warnings(&c);
        let gap = w.iter().find(|m| m.starts_with("set I (I.csv)")).unwrap();
        let (a, b) = (c.dynamic[i].t[n / 2 - 1], c.dynamic[i].t[n / 2]);
        assert!(
            gap.contains(&format!(
                "the longest 5.1 s from t = {} s to {} s (samples {} and {} of {n})",
                crate::numerics::Num(a),
                crate::numerics::Num(b),
                n / 2,
                n / 2 + 1
            )),
            "{gap}"
        );
        // (to 4 digits both ends read the same)
        assert_eq!(sig(a), sig(b), "{a} {b}");
        let text = summarize(&c).text();
        assert!(text.contains("\nwarning: set J (J.csv)"), "{text}");
    }
}
