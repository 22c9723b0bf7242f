//! `valgi eval --sweep`: the sparse method over the grid of its budget knobs (sparse points ×
//! RSM side × visibility), on every scene, so that a budget choice (`--quality auto`) can be
//! checked against the cheapest setting that reaches the same error.
//!
//! Besides the error against the path-traced reference, every grid row gets its *convergence
//! error*: the indirect FLIP against the grid's richest setting (most points, largest RSM,
//! rays at every stratum). That is the part of the error the knobs control; the rest is the
//! method's own bias, which no setting removes.

use std::fmt::Write as _;
use std::path::Path;

use super::{metrics, EvalError, EvalRow};
use crate::image_io::Image;

/// How a grid row resolves visibility: the registry's `occlusion` and `visibility-rays`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepVisibility {
    Off,
    Sum,
    RaysAdaptive,
    RaysAll,
}

impl SweepVisibility {
    pub const ALL: [SweepVisibility; 4] = [Self::Off, Self::Sum, Self::RaysAdaptive, Self::RaysAll];

    /// Cost rank, cheapest first (used to pick the richest setting of the grid).
    fn rank(self) -> u32 {
        self as u32
    }

    /// The method options this visibility stands for.
    pub fn options(self) -> &'static str {
        match self {
            Self::Off => "occlusion=off",
            Self::Sum => "occlusion=sum",
            Self::RaysAdaptive => "occlusion=rays,visibility-rays=adaptive",
            Self::RaysAll => "occlusion=rays,visibility-rays=all",
        }
    }

    /// Short name in `sweep.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Sum => "sum",
            Self::RaysAdaptive => "rays-adaptive",
            Self::RaysAll => "rays-all",
        }
    }

    pub fn parse(text: &str) -> Result<Self, EvalError> {
        Self::ALL
            .into_iter()
            .find(|v| v.name() == text)
            .ok_or_else(|| {
                EvalError::Settings(format!(
                    "--sweep-visibility {text}: expected one of {}",
                    Self::ALL.map(|v| v.name()).join(", ")
                ))
            })
    }
}

/// The grid `--sweep` renders: the Cartesian product of its three axes.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepGrid {
    pub points: Vec<u32>,
    pub rsm: Vec<u32>,
    pub visibility: Vec<SweepVisibility>,
}

impl Default for SweepGrid {
    fn default() -> Self {
        Self {
            points: vec![1024, 2048, 4096, 8192, 16384],
            rsm: vec![32, 64, 128],
            visibility: SweepVisibility::ALL.to_vec(),
        }
    }
}

/// One grid setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridSetting {
    pub points: u32,
    pub rsm: u32,
    pub visibility: SweepVisibility,
}

impl GridSetting {
    /// The `sparse:…` method spec that renders this setting.
    pub fn spec(&self) -> String {
        format!(
            "sparse:sparse-points={},rsm={},{}",
            self.points,
            self.rsm,
            self.visibility.options()
        )
    }
}

impl SweepGrid {
    pub fn settings(&self) -> Vec<GridSetting> {
        let mut out = vec![];
        for &points in &self.points {
            for &rsm in &self.rsm {
                for &visibility in &self.visibility {
                    out.push(GridSetting {
                        points,
                        rsm,
                        visibility,
                    });
                }
            }
        }
        out
    }

    /// Checks the axes before anything renders.
    pub fn check(&self) -> Result<(), EvalError> {
        if self.points.is_empty() || self.rsm.is_empty() || self.visibility.is_empty() {
            return Err(EvalError::Settings(
                "--sweep: every axis (points, rsm, visibility) needs at least one value".into(),
            ));
        }
        if let Some(p) = self.points.iter().find(|&&p| !(1..=1 << 20).contains(&p)) {
            return Err(EvalError::Settings(format!(
                "--sweep-points {p}: must be 1..=1048576"
            )));
        }
        if let Some(r) = self.rsm.iter().find(|&&r| !(1..=2048).contains(&r)) {
            return Err(EvalError::Settings(format!(
                "--sweep-rsm {r}: must be 1..=2048"
            )));
        }
        Ok(())
    }

    /// The grid's richest setting: the most points, the largest RSM, the costliest
    /// visibility. Its image is what the others converge to.
    pub fn richest(&self) -> GridSetting {
        GridSetting {
            points: *self.points.iter().max().expect("checked"),
            rsm: *self.rsm.iter().max().expect("checked"),
            visibility: *self
                .visibility
                .iter()
                .max_by_key(|v| v.rank())
                .expect("checked"),
        }
    }
}

/// One grid row of `sweep.csv`.
#[derive(Clone, Debug)]
pub struct SweepRow {
    pub scene: String,
    pub setting: GridSetting,
    pub total_ms: f64,
    pub flip: f64,
    pub flip_indirect: f64,
    /// Indirect FLIP against the richest setting's indirect image.
    pub flip_indirect_converged: f64,
}

pub const SWEEP_CSV_HEADER: &str =
    "scene,points,rsm,visibility,total_ms,flip,flip_indirect,flip_indirect_converged";

impl SweepRow {
    pub fn csv_line(&self) -> String {
        format!(
            "{},{},{},{},{:.3},{:.6},{:.6},{:.6}",
            self.scene,
            self.setting.points,
            self.setting.rsm,
            self.setting.visibility.name(),
            self.total_ms,
            self.flip,
            self.flip_indirect,
            self.flip_indirect_converged
        )
    }
}

/// A scene's grid rows with their convergence error. `rows[i]` is `settings[i]`'s row and
/// `indirect[i]` its indirect image; `exposure` is the reference indirect's tone-map exposure.
pub fn scene_rows(
    grid: &SweepGrid,
    settings: &[GridSetting],
    rows: &[&EvalRow],
    indirect: &[Image],
    exposure: f32,
) -> Vec<SweepRow> {
    let richest = grid.richest();
    let converged = settings
        .iter()
        .position(|s| *s == richest)
        .map(|i| &indirect[i]);
    settings
        .iter()
        .zip(rows)
        .zip(indirect)
        .map(|((setting, row), image)| SweepRow {
            scene: row.scene.clone(),
            setting: *setting,
            total_ms: row.total_ms,
            flip: row.flip,
            flip_indirect: row.flip_indirect,
            flip_indirect_converged: converged
                .map(|c| metrics::flip(image, c, exposure))
                .unwrap_or(f64::NAN),
        })
        .collect()
}

/// Which error a target is measured in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TargetError {
    /// Indirect FLIP against the path-traced reference.
    Reference,
    /// Indirect FLIP against the grid's richest setting.
    Converged,
}

impl TargetError {
    fn of(self, row: &SweepRow) -> f64 {
        match self {
            Self::Reference => row.flip_indirect,
            Self::Converged => row.flip_indirect_converged,
        }
    }
}

/// The cheapest row of one scene whose error is at most `target`; `None` when none is.
pub fn cheapest_meeting(rows: &[SweepRow], target: f64, error: TargetError) -> Option<&SweepRow> {
    rows.iter()
        .filter(|r| error.of(r) <= target)
        .min_by(|a, b| a.total_ms.total_cmp(&b.total_ms))
}

/// The grid row of one scene with the lowest convergence error among those whose frame took at
/// most `budget_ms`; `None` when none did.
pub fn most_accurate_within(rows: &[SweepRow], budget_ms: f64) -> Option<&SweepRow> {
    rows.iter()
        .filter(|r| r.total_ms <= budget_ms && r.flip_indirect_converged.is_finite())
        .min_by(|a, b| {
            a.flip_indirect_converged
                .total_cmp(&b.flip_indirect_converged)
                .then(a.total_ms.total_cmp(&b.total_ms))
        })
}

/// Writes `sweep.csv`.
pub fn write_csv(path: &Path, rows: &[SweepRow]) -> Result<(), EvalError> {
    let mut csv = String::new();
    let _ = writeln!(csv, "{SWEEP_CSV_HEADER}");
    for row in rows {
        let _ = writeln!(csv, "{}", row.csv_line());
    }
    std::fs::write(path, csv).map_err(|e| EvalError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// A budget-mode row against the grid: its time and convergence error beside the cheapest
/// grid setting that reaches the same convergence error target, or under a time budget the
/// most accurate grid setting whose frame fits it.
#[derive(Clone, Debug)]
pub struct AutoCheck {
    pub scene: String,
    /// The method's settings text and what budget mode chose.
    pub settings: String,
    pub chosen: String,
    pub target_flip: Option<f64>,
    pub total_ms: f64,
    pub flip_indirect: f64,
    pub flip_indirect_converged: f64,
    pub predicted_flip: f64,
    /// The cheapest grid row meeting the target, if any: its setting and time.
    pub cheapest: Option<(GridSetting, f64, f64)>,
    /// The grid row's time of the setting budget mode chose, when the grid has that setting.
    pub chosen_grid_ms: Option<f64>,
    /// Whether budget mode's report says the target is met (`budget.met`): its pilots'
    /// measurement, which also asks its converged candidate to be predicted within the target.
    pub budget_met: Option<bool>,
    /// `--budget-ms`, under a time budget.
    pub budget_ms: Option<f64>,
    /// The most accurate grid row whose frame fits the time budget, if any: its setting, time
    /// and convergence error.
    pub most_accurate_within: Option<(GridSetting, f64, f64)>,
}

impl AutoCheck {
    /// Budget mode's time over the cheapest grid setting's (≤ 1.25 is the goal).
    pub fn time_ratio(&self) -> Option<f64> {
        self.cheapest.map(|(_, ms, _)| self.total_ms / ms)
    }

    /// The same ratio with both times from grid rows, when the choice is a grid setting: two
    /// rows of one setting differ by the harness's timing noise (up to 1.3× at 128² on
    /// lavapipe), which this ratio leaves out (1 when the choice is the cheapest setting).
    pub fn grid_time_ratio(&self) -> Option<f64> {
        Some(self.chosen_grid_ms? / self.cheapest?.1)
    }

    /// Under a time budget, budget mode's frame over the budget (≤ 1 is the goal).
    pub fn budget_ratio(&self) -> Option<f64> {
        Some(self.total_ms / self.budget_ms?)
    }

    /// Under a time budget, budget mode's convergence error less that of the most accurate
    /// grid setting within the budget (≤ 0: at least as accurate).
    pub fn flip_excess(&self) -> Option<f64> {
        Some(self.flip_indirect_converged - self.most_accurate_within?.2)
    }
}

pub const CHECK_CSV_HEADER: &str = "scene,settings,chosen,target_flip,predicted_flip,total_ms,flip_indirect,flip_indirect_converged,meets_target,cheapest_grid,cheapest_ms,cheapest_flip_converged,time_ratio,chosen_grid_ms,grid_time_ratio,budget_met,budget_ms,budget_ratio,best_grid_within,best_grid_ms,best_grid_flip_converged,flip_excess";

/// A knob's value in budget mode's report: `budget.<knob>.value`.
fn knob_value<'a>(budget: &'a serde_json::Value, knob: &str) -> Option<&'a serde_json::Value> {
    budget.get(knob)?.get("value")
}

/// The grid setting budget mode's report (`budget` in the JSON line) says it chose; `None`
/// when a knob is missing or unreadable.
pub fn chosen_setting(budget: &serde_json::Value) -> Option<GridSetting> {
    let value = |knob: &str| knob_value(budget, knob);
    let number = |knob: &str| u32::try_from(value(knob)?.as_u64()?).ok();
    let visibility = match value("occlusion")?.as_str()? {
        "off" => SweepVisibility::Off,
        "sum" => SweepVisibility::Sum,
        "rays" => match value("visibility_rays")?.as_str()? {
            "adaptive" => SweepVisibility::RaysAdaptive,
            _ => SweepVisibility::RaysAll,
        },
        _ => return None,
    };
    Some(GridSetting {
        points: number("sparse_points")?,
        rsm: number("rsm")?,
        visibility,
    })
}

/// Checks one budget-mode row (`budget` is its report) against the scene's grid.
#[allow(clippy::too_many_arguments)]
pub fn check_auto(
    row: &EvalRow,
    budget: &serde_json::Value,
    indirect: &Image,
    grid: &SweepGrid,
    settings: &[GridSetting],
    grid_indirect: &[Image],
    grid_rows: &[SweepRow],
    exposure: f32,
) -> AutoCheck {
    let richest = grid.richest();
    let converged = settings
        .iter()
        .position(|s| *s == richest)
        .map(|i| metrics::flip(indirect, &grid_indirect[i], exposure))
        .unwrap_or(f64::NAN);
    let target_flip = budget.get("target_flip").and_then(|t| t.as_f64());
    let budget_ms = budget.get("budget_ms").and_then(|t| t.as_f64());
    let value = |knob: &str| {
        knob_value(budget, knob)
            .map(|v| v.to_string().trim_matches('"').to_string())
            .unwrap_or_default()
    };
    AutoCheck {
        scene: row.scene.clone(),
        settings: row.settings.clone(),
        chosen: {
            let occlusion = value("occlusion");
            let mut chosen = format!(
                "points={} rsm={} occlusion={occlusion}",
                value("sparse_points"),
                value("rsm")
            );
            if occlusion == "rays" {
                chosen += &format!(" visibility-rays={}", value("visibility_rays"));
            }
            chosen
        },
        target_flip,
        total_ms: row.total_ms,
        flip_indirect: row.flip_indirect,
        flip_indirect_converged: converged,
        predicted_flip: budget
            .get("predicted_flip")
            .and_then(|f| f.as_f64())
            .unwrap_or(f64::NAN),
        cheapest: target_flip.and_then(|t| {
            cheapest_meeting(grid_rows, t, TargetError::Converged)
                .map(|r| (r.setting, r.total_ms, r.flip_indirect_converged))
        }),
        chosen_grid_ms: chosen_setting(budget).and_then(|setting| {
            grid_rows
                .iter()
                .find(|r| r.setting == setting)
                .map(|r| r.total_ms)
        }),
        budget_met: budget.get("met").and_then(|m| m.as_bool()),
        budget_ms,
        most_accurate_within: budget_ms.and_then(|ms| {
            most_accurate_within(grid_rows, ms)
                .map(|r| (r.setting, r.total_ms, r.flip_indirect_converged))
        }),
    }
}

/// A grid row's setting, time and convergence error as `sweep_check.csv` cells: "none" where
/// the check `applies` and found no row, empty where it does not apply.
fn grid_row_cells(row: Option<(GridSetting, f64, f64)>, applies: bool) -> (String, String, String) {
    match row {
        Some((s, ms, flip)) => (
            format!("{} {} {}", s.points, s.rsm, s.visibility.name()),
            format!("{ms:.3}"),
            format!("{flip:.6}"),
        ),
        None if applies => ("none".into(), String::new(), String::new()),
        None => Default::default(),
    }
}

/// Writes `sweep_check.csv`.
pub fn write_checks(path: &Path, checks: &[AutoCheck]) -> Result<(), EvalError> {
    let mut csv = String::new();
    let _ = writeln!(csv, "{CHECK_CSV_HEADER}");
    for c in checks {
        let (grid, ms, flip) = grid_row_cells(c.cheapest, c.target_flip.is_some());
        let (best, best_ms, best_flip) =
            grid_row_cells(c.most_accurate_within, c.budget_ms.is_some());
        let _ = writeln!(
            csv,
            "{},\"{}\",{},{},{:.4},{:.3},{:.6},{:.6},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            c.scene,
            c.settings,
            c.chosen,
            c.target_flip.map(|t| t.to_string()).unwrap_or_default(),
            c.predicted_flip,
            c.total_ms,
            c.flip_indirect,
            c.flip_indirect_converged,
            c.target_flip
                .map(|t| (c.flip_indirect_converged <= t).to_string())
                .unwrap_or_default(),
            grid,
            ms,
            flip,
            c.time_ratio()
                .map(|r| format!("{r:.3}"))
                .unwrap_or_default(),
            c.chosen_grid_ms
                .map(|ms| format!("{ms:.3}"))
                .unwrap_or_default(),
            c.grid_time_ratio()
                .map(|r| format!("{r:.3}"))
                .unwrap_or_default(),
            c.budget_met.map(|m| m.to_string()).unwrap_or_default(),
            c.budget_ms.map(|ms| ms.to_string()).unwrap_or_default(),
            c.budget_ratio()
                .map(|r| format!("{r:.3}"))
                .unwrap_or_default(),
            best,
            best_ms,
            best_flip,
            c.flip_excess()
                .map(|e| format!("{e:.6}"))
                .unwrap_or_default()
        );
    }
    std::fs::write(path, csv).map_err(|e| EvalError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(points: u32, ms: f64, flip: f64, converged: f64) -> SweepRow {
        SweepRow {
            scene: "s".into(),
            setting: GridSetting {
                points,
                rsm: 32,
                visibility: SweepVisibility::Off,
            },
            total_ms: ms,
            flip: flip * 2.0,
            flip_indirect: flip,
            flip_indirect_converged: converged,
        }
    }

    #[test]
    fn the_grid_is_the_product_of_its_axes_and_its_richest_setting_is_the_costliest() {
        let grid = SweepGrid {
            points: vec![1024, 4096],
            rsm: vec![64, 32],
            visibility: vec![SweepVisibility::RaysAll, SweepVisibility::Sum],
        };
        let settings = grid.settings();
        assert_eq!(settings.len(), 8);
        assert_eq!(
            grid.richest(),
            GridSetting {
                points: 4096,
                rsm: 64,
                visibility: SweepVisibility::RaysAll
            }
        );
        assert!(settings.contains(&grid.richest()));
        assert_eq!(
            settings[0].spec(),
            "sparse:sparse-points=1024,rsm=64,occlusion=rays,visibility-rays=all"
        );
        let bad = SweepGrid {
            rsm: vec![],
            ..grid
        };
        assert!(bad.check().is_err());
    }

    #[test]
    fn the_chosen_setting_is_read_from_the_budget_report_and_timed_by_its_grid_row() {
        let report = |occlusion: &str, rays: &str| {
            serde_json::json!({
                "sparse_points": {"value": 2048, "why": ""},
                "rsm": {"value": 48, "why": ""},
                "occlusion": {"value": occlusion, "why": ""},
                "visibility_rays": {"value": rays, "why": ""},
            })
        };
        let setting = |visibility| GridSetting {
            points: 2048,
            rsm: 48,
            visibility,
        };
        assert_eq!(
            chosen_setting(&report("rays", "adaptive")),
            Some(setting(SweepVisibility::RaysAdaptive))
        );
        assert_eq!(
            chosen_setting(&report("rays", "all")),
            Some(setting(SweepVisibility::RaysAll))
        );
        assert_eq!(
            chosen_setting(&report("off", "all")),
            Some(setting(SweepVisibility::Off))
        );
        assert_eq!(chosen_setting(&report("union", "all")), None);
        assert_eq!(chosen_setting(&serde_json::json!({})), None);
        // The same setting timed twice: the row ratio carries the noise, the grid ratio not.
        let check = AutoCheck {
            scene: "s".into(),
            settings: String::new(),
            chosen: String::new(),
            target_flip: Some(0.05),
            total_ms: 130.0,
            flip_indirect: 0.1,
            flip_indirect_converged: 0.04,
            predicted_flip: 0.05,
            cheapest: Some((setting(SweepVisibility::Off), 100.0, 0.04)),
            chosen_grid_ms: Some(100.0),
            budget_met: Some(true),
            budget_ms: None,
            most_accurate_within: None,
        };
        assert_eq!(check.time_ratio(), Some(1.3));
        assert_eq!(check.grid_time_ratio(), Some(1.0));
        let off_grid = AutoCheck {
            chosen_grid_ms: None,
            ..check.clone()
        };
        assert_eq!(off_grid.grid_time_ratio(), None);
        assert_eq!((check.budget_ratio(), check.flip_excess()), (None, None));
        // Under a time budget: the frame over the budget, the error over the grid's best.
        let timed = AutoCheck {
            target_flip: None,
            cheapest: None,
            budget_ms: Some(200.0),
            most_accurate_within: Some((setting(SweepVisibility::RaysAll), 190.0, 0.03)),
            ..check
        };
        assert_eq!(timed.budget_ratio(), Some(0.65));
        assert!((timed.flip_excess().unwrap() - 0.01).abs() < 1e-12);
    }

    #[test]
    fn the_most_accurate_setting_within_a_time_budget_is_found() {
        let rows = [
            row(1024, 50.0, 0.2, 0.08),
            row(2048, 120.0, 0.15, 0.04),
            row(4096, 260.0, 0.12, 0.02),
            row(8192, 250.0, 0.12, f64::NAN),
        ];
        let best = |ms| most_accurate_within(&rows, ms).map(|r| r.setting.points);
        assert_eq!(best(40.0), None);
        assert_eq!(best(100.0), Some(1024));
        assert_eq!(
            best(255.0),
            Some(2048),
            "a row without a converged error is skipped"
        );
        assert_eq!(best(1000.0), Some(4096));
    }

    #[test]
    fn the_cheapest_setting_meeting_a_target_is_found_in_either_error() {
        let rows = vec![
            row(1024, 10.0, 0.20, 0.10),
            row(2048, 20.0, 0.15, 0.05),
            row(4096, 40.0, 0.12, 0.02),
            row(8192, 30.0, 0.13, 0.00),
        ];
        let pick = |t, e| cheapest_meeting(&rows, t, e).map(|r| r.setting.points);
        assert_eq!(pick(0.15, TargetError::Reference), Some(2048));
        // 8192 is cheaper than 4096 here (a measured time can invert the order).
        assert_eq!(pick(0.13, TargetError::Reference), Some(8192));
        assert_eq!(pick(0.11, TargetError::Reference), None);
        assert_eq!(pick(0.10, TargetError::Converged), Some(1024));
        assert_eq!(pick(0.03, TargetError::Converged), Some(8192));
    }
}
