//! A session: started (stored before any trial runs), or resumed on its stored settings
//! with its model unchanged, and what of it is planned and stored.

use super::*;

/// A session ready to run: its stored identity, settings and model.
#[derive(Debug)]
pub struct Session {
    /// Its id in the store.
    pub id: i64,
    /// The model's name.
    pub model: String,
    /// The sha256 of the model's artifact.
    pub model_sha256: String,
    /// Seed of the perturbations and the simulated scenes.
    pub seed: u64,
    /// Its settings.
    pub plan: TrialPlan,
    /// One scene per medium.
    pub scenes: Vec<SceneSpec>,
    /// The model's artifact.
    pub(super) model_bytes: Vec<u8>,
    /// Each (scene index, object)'s stiffness calibration, made or found before any
    /// trial ran, and the δ the closed loop uses on it.
    pub calibrations: std::collections::HashMap<(u32, String), run::ObjectSetup>,
}

impl Session {
    /// One line per calibrated object: the calibration used, Λ_max from the model's
    /// estimate beside the simulator's truth, K, and δ (and why it was widened).
    #[must_use]
    pub fn setup_lines(&self) -> Vec<String> {
        let mut keys: Vec<&(u32, String)> = self.calibrations.keys().collect();
        keys.sort();
        let keys_in_order = keys.clone();
        // The scene values set for the session first: every result below is theirs.
        let sets = (!self.plan.sets.is_empty())
            .then(|| format!("scene values set: {}", self.plan.sets.join(", ")));
        // How each scene's frames are read: the tare, or a warning that water frames
        // go to a model as they come.
        let tares = self.scenes.iter().enumerate().filter_map(|(i, scene)| {
            match self.plan.scene_tare(i) {
                Some(t) => Some(format!("`{}`: {}", scene.name, t.describe())),
                None if scene.medium == softtouch_schemas::Medium::Water => Some(format!(
                    "`{}`: no image tare: the model reads the water frames as they come (--tare fits one from rest frames)",
                    scene.name
                )),
                None => None,
            }
        });
        // `--tare` with no water scene: nothing to fit, said rather than silent.
        let no_water = (self.plan.tare
            && !self
                .scenes
                .iter()
                .any(|s| s.medium == softtouch_schemas::Medium::Water))
        .then(|| {
            "--tare: no water scene in this session, so no image tare was fitted (land frames are read as the model learned them)"
                .to_owned()
        });
        sets.into_iter()
            .chain(no_water)
            .chain(tares)
            .chain(keys.into_iter()
            .filter_map(|k| {
                let o = self.calibrations.get(k)?;
                let medium = self
                    .scenes
                    .get(k.0 as usize)
                    .map_or("?", |s| medium_name(s.medium));
                let c = &o.calibration;
                let gain = self.plan.gain_over_lambda * c.lambda_max().max(0.05);
                // Method S4 on the calibrated Λ_max, said with the calibration's number.
                let s4 = match softtouch_grasp::check_gain(gain, c.lambda_max()) {
                    Ok(softtouch_grasp::GainCheck::Converges { contraction_at_max }) => {
                        format!("S4: K > Λ_max/2, the error × {contraction_at_max:.2} a step at Λ_max")
                    }
                    Ok(softtouch_grasp::GainCheck::MayNotConverge { amplification }) => format!(
                        "warning (S4, calibration #{}): K ≤ Λ_max/2, the loop may oscillate (× {amplification:.2} a step)",
                        c.row.calibration_id
                    ),
                    Ok(softtouch_grasp::GainCheck::NoStiffness) | Err(_) => format!(
                        "warning (S4, calibration #{}): no usable stiffness",
                        c.row.calibration_id
                    ),
                };
                // Two objects that meet the fingers alike (the same width across the
                // grasp axis at the same height: a round and an oval tube at yaw 0)
                // close alike, count for count; said, so no one looks for a bug.
                let twin = keys_in_order
                    .iter()
                    .take_while(|j| **j != k)
                    .filter(|j| j.0 == k.0)
                    .find_map(|j| {
                        let other = &self.calibrations.get(*j)?.calibration.row;
                        (other.points_json == c.row.points_json).then(|| {
                            format!(
                                "; the same closing as `{}`'s, count for count: the fingers meet the same section across the grasp axis (its depth does not enter a closing)",
                                j.1
                            )
                        })
                    })
                    .unwrap_or_default();
                let dither = if o.tolerance_n < o.count_n / 2.0 {
                    "; δ is under half a count: the loop dithers by one count around F_ref, which the confirmation accepts when its mean is within δ"
                } else {
                    ""
                };
                Some(format!(
                    "`{}` ({medium}): calibration #{} ({}): first touch at count {}, Λ_max = {:.3} N/mm from the model's estimate{}; K = {:.3} N/mm, δ = {} N{}; {s4}{dither}{twin}",
                    k.1,
                    c.row.calibration_id,
                    if c.fresh { "made now" } else { "stored" },
                    c.touch(),
                    c.lambda_max(),
                    c.row.true_lambda_max_n_per_mm.map_or_else(String::new, |t| format!(
                        " (true {t:.3}, a check only)"
                    )),
                    gain,
                    o.tolerance_n,
                    if o.tolerance_n > self.plan.tolerance_n {
                        format!(
                            " (widened from {} N: one count is {:.3} N here, and a loop dithering by one count confirms only within a quarter of it)",
                            self.plan.tolerance_n, o.count_n
                        )
                    } else {
                        String::new()
                    }
                ) + &c.accepted_against.as_ref().map_or_else(String::new, |r| {
                    format!("; ACCEPTED against its check (--accept-calibration): {r}")
                }))
            }))
            .collect()
    }
}

/// A new session of `plan` (checked) with `model` on `scenes`, stored before any
/// trial runs. With no objects in the plan, every object of the first scene.
///
/// # Errors
/// Bad settings or objects, an unknown model, the store.
pub async fn start_session(
    store: &Store,
    model: &str,
    seed: u64,
    plan: TrialPlan,
    scenes: Vec<SceneSpec>,
) -> Result<Session, TrialsError> {
    let mut plan = plan.checked()?;
    if plan.objects.is_empty() {
        plan.objects = scenes
            .first()
            .map(|s| s.objects.iter().map(|o| o.name.clone()).collect())
            .unwrap_or_default();
    }
    let objects = objects_of(&plan, &scenes)?; // checked before anything is stored
    // The model must exist before a session names it.
    let model_bytes = crate::models::force_artifact(store, model).await?;
    plan.scene_tares.clear();
    if plan.tare {
        // Each water scene's tare, fitted once and stored with the session.
        for scene in &scenes {
            plan.scene_tares
                .push(if scene.medium == softtouch_schemas::Medium::Water {
                    Some(
                        crate::grasp::tare::fit_scene_tare(
                            store,
                            model,
                            &model_bytes,
                            scene,
                            plan.fps,
                            seed,
                        )
                        .await?,
                    )
                } else {
                    None
                });
        }
    }
    // Every object calibrated (or its stored calibration found) before the session is
    // stored: an object the fingers never touch leaves no empty session.
    let pairs = (0..scenes.len()).flat_map(|si| {
        plan.objects
            .iter()
            .map(move |o| (u32::try_from(si).unwrap_or(u32::MAX), o.clone()))
    });
    let pairs: Vec<(u32, String)> = pairs.collect();
    let calibrations = run::calibrate_all(
        store,
        model,
        &model_bytes,
        seed,
        &plan,
        &scenes,
        &objects,
        pairs,
    )
    .await?;
    let model_sha256 = sha256_hex(&model_bytes);
    let config_json = serde_json::to_string(&plan)
        .map_err(|e| TrialsError::Failed(format!("cannot encode the settings: {e}")))?;
    let scenes_json = serde_json::to_string(&scenes)
        .map_err(|e| TrialsError::Failed(format!("cannot encode the scenes: {e}")))?;
    let id = store
        .create_grasp_session(model, &model_sha256, seed, &scenes_json, &config_json)
        .await?;
    Ok(Session {
        id,
        model: model.to_owned(),
        model_sha256,
        seed,
        plan,
        scenes,
        model_bytes,
        calibrations,
    })
}

/// Stored session `id` and its settings, for a resume on the simulator or a rig:
/// `model`, when given, must be the session's.
///
/// # Errors
/// No such session, another model, stored settings that do not read back, the store.
pub(crate) async fn stored_session(
    store: &Store,
    id: i64,
    model: Option<&str>,
) -> Result<(crate::store::GraspSessionRow, TrialPlan), TrialsError> {
    let s = store.grasp_session(id).await?.ok_or_else(|| {
        invalid(format!(
            "--resume {id}: no grasp session {id} in {}",
            store.target().display()
        ))
    })?;
    if let Some(m) = model
        && m != s.model
    {
        return Err(invalid(format!(
            "--model {m}: session {id} runs model `{}` (leave --model out to resume it)",
            s.model
        )));
    }
    let plan: TrialPlan = serde_json::from_str(&s.config_json).map_err(|e| {
        TrialsError::Failed(format!(
            "grasp session {id}: stored settings do not read back: {e}"
        ))
    })?;
    Ok((s, plan))
}

/// The artifact of a stored session's model and its sha256, refused if the model
/// changed under its name since the session started.
///
/// # Errors
/// A changed or missing model, the store.
pub(crate) async fn unchanged_model(
    store: &Store,
    s: &crate::store::GraspSessionRow,
) -> Result<(Vec<u8>, String), TrialsError> {
    let model_bytes = crate::models::force_artifact(store, &s.model).await?;
    let now = sha256_hex(&model_bytes);
    if let Some(then) = &s.model_sha256
        && *then != now
    {
        return Err(invalid(format!(
            "--resume {}: model `{}` has changed since the session started (sha256 {} then, {} now); start a new session",
            s.session_id,
            s.model,
            &then[..then.len().min(12)],
            &now[..12]
        )));
    }
    Ok((model_bytes, now))
}

/// Stored session `id`, on its stored settings. `model`, when given, must be the
/// session's; the model must not have changed under its name since.
///
/// # Errors
/// No such session, another model, a changed model, stored settings that do not
/// read back, the store.
pub async fn resume_session(
    store: &Store,
    id: i64,
    model: Option<&str>,
) -> Result<Session, TrialsError> {
    let (s, plan) = stored_session(store, id, model).await?;
    if plan.rig.is_some() {
        return Err(invalid(format!(
            "--resume {id}: session {id} ran on a rig: resume it with --rig FILE --resume {id}"
        )));
    }
    let scenes: Vec<SceneSpec> = serde_json::from_str(&s.scenes_json).map_err(|e| {
        TrialsError::Failed(format!(
            "grasp session {id}: stored scenes do not read back: {e}"
        ))
    })?;
    let (model_bytes, now) = unchanged_model(store, &s).await?;
    let objects = objects_of(&plan, &scenes)?;
    let pairs: Vec<(u32, String)> = (0..scenes.len())
        .flat_map(|si| {
            plan.objects
                .iter()
                .map(move |o| (u32::try_from(si).unwrap_or(u32::MAX), o.clone()))
        })
        .collect();
    let calibrations = run::calibrate_all(
        store,
        &s.model,
        &model_bytes,
        s.seed,
        &plan,
        &scenes,
        &objects,
        pairs,
    )
    .await?;
    Ok(Session {
        id,
        model: s.model,
        model_sha256: now,
        seed: s.seed,
        plan,
        scenes,
        model_bytes,
        calibrations,
    })
}

/// What is planned and stored of a session.
#[derive(Debug, Clone)]
pub struct Progress {
    /// Every trial of the plan.
    pub planned: Vec<Planned>,
    /// Those not stored yet, in the order they run.
    pub todo: Vec<Planned>,
}

impl Session {
    /// The plan's trials and those still to run.
    ///
    /// # Errors
    /// A damaged stored plan, the store.
    pub async fn progress(&self, store: &Store) -> Result<Progress, TrialsError> {
        let modes = self.plan.parsed_modes()?;
        let planned = planned(&self.plan, self.scenes.len(), &modes);
        let done = store.grasp_trial_keys(self.id).await?;
        let todo = planned
            .iter()
            .filter(|p| !done.contains(&p.key))
            .cloned()
            .collect();
        Ok(Progress { planned, todo })
    }
}
