//! Timing pilots for `--budget-ms`: the survey's time model, fitted on lavapipe at 128²
//! and scaled to another device by its FMA peak, puts every frame's fixed passes (shadow
//! maps, RSM, G-buffer, direct light, interpolation, apply) at one figure whatever the
//! image size. At 1280×720 on lavapipe a 300 ms budget then chose settings whose frames
//! took 400–410 ms on the Cornell box and 535–540 ms in the door room; on the H200 those
//! passes took 1.4 ms at 256² and 3.7 ms at 1080p against a predicted 0.23 ms. So the
//! candidates are timed: each pilot renders [`TIMING_FRAMES`] frames of a candidate at the
//! render's own size on the render's device, and the frame times measured so far refit the
//! prediction ([`TimeFit`]) before the next candidate is picked.
//!
//! The search ([`search`]): the most accurate candidate (lowest predicted convergence FLIP)
//! whose time — measured if a pilot measured it, else the fit's — is within the budget is
//! timed next (the cheapest candidate when none is), until it is one already timed or the
//! pilots run out. The choice is the most
//! accurate candidate *measured* within the budget; failing that, the one the fit puts
//! within it, unmeasured; failing that, the cheapest by the fit, marked as missing it.

use super::{BudgetChoice, Visibility};

/// Frames a timing pilot renders; the first, which pays for first use (pipelines, buffers
/// written once), is not counted, and the longest of the rest is the candidate's time.
pub const TIMING_FRAMES: usize = 3;

/// How far apart (max over min) the predicted work of the timed candidates must lie before
/// their times fit a slope of their own: closer than this, timing noise (±10 % between
/// frames on a shared CPU) would set the slope.
pub const SLOPE_SPREAD: f64 = 1.5;

/// A frame time as the timing pilots model it: `fixed_ms + work_scale · w`, with w the
/// survey's predicted time of the work the knobs set (gather pairs, visibility rays, the
/// discs' walk), its predicted frame time less its predicted fixed part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeFit {
    pub fixed_ms: f64,
    pub work_scale: f64,
}

impl TimeFit {
    /// The survey's own prediction: its fixed part, its work as priced.
    pub fn predicted(fixed_predicted_ms: f64) -> TimeFit {
        TimeFit {
            fixed_ms: fixed_predicted_ms,
            work_scale: 1.0,
        }
    }

    pub fn time_ms(&self, work_ms: f64) -> f64 {
        self.fixed_ms + self.work_scale * work_ms
    }

    /// The fit to measured `(work, frame time)` pairs (non-finite ones ignored). The fixed
    /// part is what the survey knows least (it depends on the image size and the device's
    /// raster passes), the work is priced by rates measured per pair and per ray; so with
    /// one level of work the work is taken as priced and the rest of the measured time is
    /// the fixed part (or, measured below the priced work alone, the work is scaled down
    /// and nothing is fixed). With work levels [`SLOPE_SPREAD`] apart the pairs fit both,
    /// by least squares, kept non-negative.
    pub fn fit(measured: &[(f64, f64)], fixed_predicted_ms: f64) -> TimeFit {
        let pairs: Vec<(f64, f64)> = measured
            .iter()
            .copied()
            .filter(|(w, t)| w.is_finite() && t.is_finite() && *w >= 0.0 && *t >= 0.0)
            .collect();
        if pairs.is_empty() {
            return TimeFit::predicted(fixed_predicted_ms);
        }
        let n = pairs.len() as f64;
        let work_mean = pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let time_mean = pairs.iter().map(|p| p.1).sum::<f64>() / n;
        let work_min = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let work_max = pairs.iter().map(|p| p.0).fold(0.0, f64::max);
        if work_max > 0.0 && work_max >= SLOPE_SPREAD * work_min {
            let sww: f64 = pairs.iter().map(|(w, _)| (w - work_mean).powi(2)).sum();
            let swt: f64 = pairs
                .iter()
                .map(|(w, t)| (w - work_mean) * (t - time_mean))
                .sum();
            let slope = swt / sww;
            if slope > 0.0 {
                let fixed = time_mean - slope * work_mean;
                if fixed >= 0.0 {
                    return TimeFit {
                        fixed_ms: fixed,
                        work_scale: slope,
                    };
                }
                // A line through the origin.
                let through_origin = pairs.iter().map(|(w, t)| w * t).sum::<f64>()
                    / pairs.iter().map(|(w, _)| w * w).sum::<f64>();
                return TimeFit {
                    fixed_ms: 0.0,
                    work_scale: through_origin,
                };
            }
            // Times that fall as the work grows are noise: one level of work, as below.
        }
        if work_mean <= 0.0 {
            return TimeFit {
                fixed_ms: time_mean,
                work_scale: 1.0,
            };
        }
        if time_mean >= work_mean {
            TimeFit {
                fixed_ms: time_mean - work_mean,
                work_scale: 1.0,
            }
        } else {
            TimeFit {
                fixed_ms: 0.0,
                work_scale: time_mean / work_mean,
            }
        }
    }
}

/// One timing pilot: a candidate and its frame time at the render's size (NaN when it could
/// not be rendered).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedPilot {
    pub choice: BudgetChoice,
    pub measured_ms: f64,
}

/// What [`search`] chose and the pilots it timed on the way.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeSearch {
    /// The choice, `met` false when neither a measurement nor the fit puts any candidate
    /// within the budget.
    pub choice: BudgetChoice,
    /// The choice's measured frame time, `None` when no pilot timed it.
    pub measured_ms: Option<f64>,
    /// The fit to every pilot's time.
    pub fit: TimeFit,
    /// Every pilot, in the order rendered.
    pub pilots: Vec<TimedPilot>,
}

/// A candidate's predicted work, ms: its predicted frame time less the predicted fixed part.
fn work_ms(c: &BudgetChoice, fixed_predicted_ms: f64) -> f64 {
    (c.predicted_ms - fixed_predicted_ms).max(0.0)
}

/// [`TimeFit::fit`] to the pilots' times against their candidates' predicted work.
fn fit_to(pilots: &[TimedPilot], fixed_predicted_ms: f64) -> TimeFit {
    let measured: Vec<(f64, f64)> = pilots
        .iter()
        .map(|p| (work_ms(&p.choice, fixed_predicted_ms), p.measured_ms))
        .collect();
    TimeFit::fit(&measured, fixed_predicted_ms)
}

impl TimeSearch {
    /// Adds a pilot timed after the search (the accuracy pilots' choice) and refits.
    pub fn add_pilot(&mut self, pilot: TimedPilot, fixed_predicted_ms: f64) {
        self.pilots.push(pilot);
        self.fit = fit_to(&self.pilots, fixed_predicted_ms);
    }

    /// A candidate's frame time by what the search knows: a pilot's measurement (NaN for one
    /// that failed), else the fit. `fixed_predicted_ms` as given to [`search`].
    pub fn time_of(&self, c: &BudgetChoice, fixed_predicted_ms: f64) -> f64 {
        self.pilots
            .iter()
            .find(|p| p.choice.same_setting(c))
            .map(|p| p.measured_ms)
            .unwrap_or_else(|| self.fit.time_ms(work_ms(c, fixed_predicted_ms)))
    }
}

/// Chooses among `candidates` for a frame time of `budget_ms` (module docs), timing at most
/// `max_pilots` of them with `measure` (a frame time in ms; NaN for one that failed).
/// `fixed_predicted_ms` is the survey's predicted fixed part, which every candidate's
/// `predicted_ms` includes. `sum` is no candidate: its prediction of FLIP is a placeholder
/// only FLIP pilots correct. `None` when no candidate is left.
pub fn search<E>(
    candidates: &[BudgetChoice],
    budget_ms: f64,
    fixed_predicted_ms: f64,
    max_pilots: usize,
    mut measure: impl FnMut(&BudgetChoice) -> Result<f64, E>,
) -> Result<Option<TimeSearch>, E> {
    let candidates: Vec<&BudgetChoice> = candidates
        .iter()
        .filter(|c| c.visibility != Visibility::Sum)
        .collect();
    if candidates.is_empty() {
        return Ok(None);
    }
    let work = |c: &BudgetChoice| work_ms(c, fixed_predicted_ms);
    let fit_of = |pilots: &[TimedPilot]| fit_to(pilots, fixed_predicted_ms);
    let timed = |pilots: &[TimedPilot], c: &BudgetChoice| {
        pilots
            .iter()
            .find(|p| p.choice.same_setting(c))
            .map(|p| p.measured_ms)
    };
    let most_accurate = |a: &&&BudgetChoice, b: &&&BudgetChoice| {
        a.predicted_flip
            .total_cmp(&b.predicted_flip)
            .then(a.predicted_ms.total_cmp(&b.predicted_ms))
    };
    // The candidates within the budget by what is known: a pilot's measurement (a failed
    // one, NaN, is within no budget), else the fit.
    let within = |pilots: &[TimedPilot], fit: &TimeFit| -> Option<&BudgetChoice> {
        candidates
            .iter()
            .filter(|c| {
                let ms = timed(pilots, c).unwrap_or_else(|| fit.time_ms(work(c)));
                ms <= budget_ms
            })
            .min_by(most_accurate)
            .copied()
    };
    // The cheapest candidate by what is known (a failed pilot, NaN, is the dearest).
    let cheapest = |pilots: &[TimedPilot], fit: &TimeFit| -> Option<&BudgetChoice> {
        let time = |c: &BudgetChoice| {
            timed(pilots, c)
                .map(|ms| if ms.is_nan() { f64::INFINITY } else { ms })
                .unwrap_or_else(|| fit.time_ms(work(c)))
        };
        candidates
            .iter()
            .min_by(|a, b| time(a).total_cmp(&time(b)))
            .copied()
    };
    let mut pilots: Vec<TimedPilot> = vec![];
    while pilots.len() < max_pilots {
        let fit = fit_of(&pilots);
        // With nothing within the budget by the fit, the cheapest candidate is timed: it
        // may fit after all, and its work, far from the others', gives the fit its slope.
        let Some(next) = within(&pilots, &fit).or_else(|| cheapest(&pilots, &fit)) else {
            break;
        };
        if timed(&pilots, next).is_some() {
            break;
        }
        let measured_ms = measure(next)?;
        pilots.push(TimedPilot {
            choice: *next,
            measured_ms,
        });
    }
    let fit = fit_of(&pilots);
    let measured_within = pilots
        .iter()
        .filter(|p| p.measured_ms <= budget_ms)
        .min_by(|a, b| most_accurate(&&&a.choice, &&&b.choice));
    let (choice, measured_ms, met) = if let Some(p) = measured_within {
        (p.choice, Some(p.measured_ms), true)
    } else if let Some(c) = within(&pilots, &fit) {
        (*c, timed(&pilots, c), true)
    } else {
        // Nothing within the budget: the cheapest by what is known.
        let Some(cheapest) = cheapest(&pilots, &fit) else {
            return Ok(None);
        };
        (*cheapest, timed(&pilots, cheapest), false)
    };
    Ok(Some(TimeSearch {
        choice: BudgetChoice { met, ..choice },
        measured_ms,
        fit,
        pilots,
    }))
}

#[cfg(test)]
mod tests {
    use super::super::tests::survey_of;
    use super::super::{BudgetTarget, Survey, DEFAULT_PILOTS};
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
    }

    #[test]
    fn one_level_of_work_is_taken_as_priced_and_two_fit_a_line() {
        let fixed_predicted = 60.0;
        // Without a measurement, the survey's prediction.
        assert_eq!(TimeFit::fit(&[], fixed_predicted), TimeFit::predicted(60.0));
        // One measurement: the rest of its time is fixed...
        let one = TimeFit::fit(&[(100.0, 400.0)], fixed_predicted);
        assert!(
            close(one.fixed_ms, 300.0) && close(one.work_scale, 1.0),
            "{one:?}"
        );
        // ...or, below the priced work alone, the work is scaled down.
        let fast = TimeFit::fit(&[(100.0, 50.0)], fixed_predicted);
        assert!(
            close(fast.fixed_ms, 0.0) && close(fast.work_scale, 0.5),
            "{fast:?}"
        );
        // Work levels 1.5× apart or more fit both parts.
        let line = TimeFit::fit(&[(100.0, 300.0), (400.0, 900.0)], fixed_predicted);
        assert!(
            close(line.fixed_ms, 100.0) && close(line.work_scale, 2.0),
            "{line:?}"
        );
        // Closer than that, noise would set the slope: one level, the mean.
        let near = TimeFit::fit(&[(100.0, 300.0), (120.0, 280.0)], fixed_predicted);
        assert!(
            close(near.fixed_ms, 180.0) && close(near.work_scale, 1.0),
            "{near:?}"
        );
        // A line that would put the fixed part below zero goes through the origin.
        let origin = TimeFit::fit(&[(100.0, 100.0), (400.0, 700.0)], fixed_predicted);
        assert!(close(origin.fixed_ms, 0.0), "{origin:?}");
        assert!(close(
            origin.work_scale,
            (100.0 * 100.0 + 400.0 * 700.0) / 170_000.0
        ));
        // Times falling as the work grows are noise; failed pilots are left out.
        let noisy = TimeFit::fit(
            &[(100.0, 500.0), (400.0, 450.0), (200.0, f64::NAN)],
            fixed_predicted,
        );
        assert!(
            close(noisy.fixed_ms, 225.0) && close(noisy.work_scale, 1.0),
            "{noisy:?}"
        );
    }

    /// The search against a device whose frame takes `truth`.
    fn search_against(
        survey: &Survey,
        budget_ms: f64,
        max_pilots: usize,
        truth: impl Fn(&BudgetChoice) -> f64,
    ) -> TimeSearch {
        let candidates = survey.candidates(|_, _, _| true);
        search(
            &candidates,
            budget_ms,
            survey.predicted_fixed_ms(),
            max_pilots,
            |c| Ok::<_, ()>(truth(c)),
        )
        .unwrap()
        .expect("candidates")
    }

    /// The most accurate candidate (no `sum`) whose true time is within `budget_ms`.
    fn best_within(
        survey: &Survey,
        budget_ms: f64,
        truth: impl Fn(&BudgetChoice) -> f64,
    ) -> BudgetChoice {
        survey
            .candidates(|_, _, v| v != Visibility::Sum)
            .into_iter()
            .filter(|c| truth(c) <= budget_ms)
            .min_by(|a, b| {
                a.predicted_flip
                    .total_cmp(&b.predicted_flip)
                    .then(a.predicted_ms.total_cmp(&b.predicted_ms))
            })
            .expect("a candidate within the budget")
    }

    /// A device whose fixed passes cost what the survey does not know (a larger image, other
    /// raster hardware) and whose work runs at another rate: the timing pilots find the
    /// most accurate candidate within the budget, where the survey's prediction alone
    /// overspends or underspends.
    #[test]
    fn timing_pilots_find_the_most_accurate_candidate_within_the_budget() {
        for name in ["cornell", "door-room"] {
            let survey = survey_of(name);
            let fixed = survey.predicted_fixed_ms();
            for (true_fixed, true_scale, budget) in
                // The last: the first candidate timed puts the fixed part alone past the
                // budget by one level of work; the cheapest, timed, fits and sets the slope.
                [
                    (300.0, 1.0, 500.0),
                    (250.0, 1.6, 600.0),
                    (5.0, 0.4, 80.0),
                    (250.0, 2.5, 320.0),
                ]
            {
                let truth = |c: &BudgetChoice| true_fixed + true_scale * (c.predicted_ms - fixed);
                let found = search_against(&survey, budget, DEFAULT_PILOTS, truth);
                let best = best_within(&survey, budget, truth);
                let case = format!("{name}, fixed {true_fixed}, scale {true_scale}");
                assert!(
                    found.choice.same_setting(&best),
                    "{case}: {found:?}, best {best:?}"
                );
                assert!(found.choice.met, "{case}");
                let measured = found.measured_ms.expect("the choice was timed");
                assert!(
                    measured <= budget && close(measured, truth(&best)),
                    "{case}"
                );
                // The survey alone takes another setting: the pilots are what found it.
                let unmeasured = survey.choose(BudgetTarget::Ms(budget));
                assert!(!unmeasured.same_setting(&best), "{case}: {unmeasured:?}");
                // Few pilots, none timed twice.
                assert!(found.pilots.len() <= DEFAULT_PILOTS, "{case}");
                for (i, p) in found.pilots.iter().enumerate() {
                    assert!(found.pilots[..i]
                        .iter()
                        .all(|q| !q.choice.same_setting(&p.choice)));
                }
            }
        }
    }

    #[test]
    fn without_pilots_the_survey_chooses_and_beyond_every_candidate_the_cheapest_misses() {
        let survey = survey_of("cornell");
        let fixed = survey.predicted_fixed_ms();
        let budget = 200.0;
        let truth = |c: &BudgetChoice| 150.0 + 2.0 * (c.predicted_ms - fixed);
        let alone = search_against(&survey, budget, 0, truth);
        assert!(alone.pilots.is_empty() && alone.measured_ms.is_none());
        assert!(alone
            .choice
            .same_setting(&survey.choose(BudgetTarget::Ms(budget))));
        // Fixed passes alone past the budget: the cheapest candidate, said to miss it.
        let slow = |c: &BudgetChoice| 1000.0 + (c.predicted_ms - fixed);
        let missed = search_against(&survey, budget, DEFAULT_PILOTS, slow);
        let cheapest = survey
            .candidates(|_, _, v| v != Visibility::Sum)
            .into_iter()
            .min_by(|a, b| slow(a).total_cmp(&slow(b)))
            .unwrap();
        // A pilot timed after the search (the accuracy pilots' choice) refits the times.
        let mut refitted = alone.clone();
        let extra = TimedPilot {
            choice: cheapest,
            measured_ms: slow(&cheapest),
        };
        refitted.add_pilot(extra, fixed);
        assert_eq!(refitted.pilots, vec![extra]);
        let expected = TimeFit::fit(&[(cheapest.predicted_ms - fixed, extra.measured_ms)], fixed);
        assert_eq!(refitted.fit, expected);
        assert_ne!(refitted.fit, alone.fit);
        assert!(!missed.choice.met, "{missed:?}");
        assert!(missed.choice.same_setting(&cheapest), "{missed:?}");
        assert_eq!(
            missed.measured_ms,
            Some(slow(&cheapest)),
            "timed to be sure"
        );
        assert!(missed.pilots.len() <= 3, "{missed:?}");
    }

    #[test]
    fn a_candidate_that_fails_to_render_is_within_no_budget() {
        let survey = survey_of("cornell");
        let fixed = survey.predicted_fixed_ms();
        let budget = 400.0;
        let ok = |c: &BudgetChoice| 200.0 + (c.predicted_ms - fixed);
        let first = search_against(&survey, budget, 1, ok).pilots[0].choice;
        // The first candidate timed fails (beyond the device's memory, say).
        let failing = |c: &BudgetChoice| {
            if c.same_setting(&first) {
                f64::NAN
            } else {
                ok(c)
            }
        };
        let found = search_against(&survey, budget, DEFAULT_PILOTS, failing);
        assert!(!found.choice.same_setting(&first), "{found:?}");
        assert!(found.choice.met && found.measured_ms.is_some_and(|ms| ms <= budget));
        // `sum` is no candidate of a time budget.
        assert!(found
            .pilots
            .iter()
            .all(|p| p.choice.visibility != Visibility::Sum));
    }
}
