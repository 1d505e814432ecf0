//! The grasp sessions the page shows: each stored session's plan read back, its
//! trials summarised by the same table `grasp trials` prints ([`summarise`]), and the
//! traces of the trials the viewer draws (the first failure of each kind and the first
//! success of each medium and mode).

use softtouch_schemas::{Medium, SceneSpec};

use super::ReportError;
use super::data::ReadOnly;
use crate::grasp::trials::table::{Cell, summarise};
use crate::grasp::trials::{TrialPlan, medium_name};
use crate::store::report::{grasp_sessions, grasp_trace};
use crate::store::{GraspSessionRow, GraspTrace, GraspTrialRow};

/// A grasp session as the page shows it.
#[derive(Debug, Clone)]
pub(crate) struct GraspData {
    pub session: GraspSessionRow,
    /// Its settings (`None`: they do not read back; see `problems`).
    pub plan: Option<TrialPlan>,
    /// One medium per scene (a rig session: one).
    pub media: Vec<Medium>,
    pub rows: Vec<GraspTrialRow>,
    /// The table `grasp trials` prints.
    pub cells: Vec<Cell>,
    /// The trials the viewer draws, with their traces.
    pub viewed: Vec<(GraspTrialRow, Option<GraspTrace>)>,
    /// Each scene's physics cap (a simulated session whose scenes read back).
    pub caps: Vec<crate::grasp::trials::cap::SceneCap>,
    /// What could not be read.
    pub problems: Vec<String>,
}

impl GraspData {
    /// `rig` or `simulator`.
    pub(crate) fn kind(&self) -> &'static str {
        if self.plan.as_ref().is_some_and(|p| p.rig.is_some()) {
            "rig"
        } else {
            "simulator"
        }
    }
}

/// The trials to draw: the first failure of each reason and the first success of
/// each medium and mode, in the order they were stored.
fn chosen(rows: &[GraspTrialRow]) -> Vec<&GraspTrialRow> {
    let mut seen: Vec<String> = Vec::new();
    rows.iter()
        .filter(|r| {
            let key = match &r.reason {
                Some(reason) if reason == "refused" => return false,
                Some(reason) => format!("fail {reason}"),
                None => format!("held {} {}", r.medium, r.key.mode),
            };
            if seen.contains(&key) {
                false
            } else {
                seen.push(key);
                true
            }
        })
        .collect()
}

pub(crate) async fn gather(db: &ReadOnly) -> Result<Vec<GraspData>, ReportError> {
    let mut out = Vec::new();
    for (session, rows) in grasp_sessions(db).await? {
        let mut problems = Vec::new();
        let plan = serde_json::from_str::<TrialPlan>(&session.config_json)
            .map_err(|e| problems.push(format!("stored settings: {e}")))
            .ok();
        let mut caps = Vec::new();
        let media: Vec<Medium> = match plan.as_ref().and_then(|p| p.rig.as_ref()) {
            Some(rig) => vec![rig.grasp.medium],
            None => serde_json::from_str::<Vec<SceneSpec>>(&session.scenes_json)
                .map(|scenes| {
                    if let Some(p) = &plan {
                        caps =
                            crate::grasp::trials::cap::scene_caps(p, &scenes).unwrap_or_else(|e| {
                                problems.push(format!("the physics cap: {e}"));
                                Vec::new()
                            });
                    }
                    scenes.iter().map(|s| s.medium).collect()
                })
                .unwrap_or_else(|e| {
                    problems.push(format!("stored scenes: {e}"));
                    Vec::new()
                }),
        };
        let cells = match &plan {
            Some(p) => summarise(p, &media, &rows).unwrap_or_else(|e| {
                problems.push(format!("the table: {e}"));
                Vec::new()
            }),
            None => Vec::new(),
        };
        let mut viewed = Vec::new();
        for r in chosen(&rows) {
            let trace = match grasp_trace(db, session.session_id, &r.key).await {
                Ok(t) => t,
                // One damaged trace costs its figure, not the page.
                Err(e) => {
                    problems.push(format!(
                        "trace of {} {} #{}: {e}",
                        r.key.object, r.key.mode, r.key.trial
                    ));
                    None
                }
            };
            viewed.push((r.clone(), trace));
        }
        out.push(GraspData {
            session,
            plan,
            media,
            rows,
            cells,
            viewed,
            caps,
            problems,
        });
    }
    Ok(out)
}

/// A medium's name as the tables give it.
pub(crate) fn medium(m: Medium) -> &'static str {
    medium_name(m)
}
