//! A session's scenes: the scene files or the built-in ones with `--set` applied, a
//! swept scene value ([`SceneSweep`]), and the plan's objects checked in every scene.

use super::*;

/// A scene value swept over a session, stored with its plan: the session's scenes are
/// the base scenes (one per medium), `per_value` of them, at each value in turn, so
/// scene `i` has value `i / per_value`. Every value runs the same trials: the
/// perturbations and the scenes' seeds depend on the seed, the object and the trial,
/// never on the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSweep {
    /// Dotted path of the value (`objects.bottle.wet_friction`).
    pub path: String,
    /// The values as typed.
    pub values: Vec<String>,
    /// Base scenes per value.
    pub per_value: u32,
    /// The value the scenes ship with, where they all have one and agree (marked on
    /// the charts; the paper gives no value for a scene's physics).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shipped: Option<String>,
}

impl SceneSweep {
    /// Value `i` as the charts label it: `0.05 (shipped)` for the scenes' own value.
    #[must_use]
    pub fn value_label(&self, i: usize) -> String {
        let v = self.values.get(i).map_or("?", String::as_str);
        if self.shipped.as_deref() == Some(v) {
            format!("{v} (shipped)")
        } else {
            v.to_owned()
        }
    }

    /// The swept value of scene `scene_index`.
    #[must_use]
    pub fn value_of(&self, scene_index: u32) -> Option<&str> {
        let i = scene_index.checked_div(self.per_value)? as usize;
        self.values.get(i).map(String::as_str)
    }

    /// Which value scene `scene_index` has.
    #[must_use]
    pub fn value_index(&self, scene_index: u32) -> Option<usize> {
        let i = scene_index.checked_div(self.per_value)? as usize;
        (i < self.values.len()).then_some(i)
    }
}

/// The scenes of `paths` (one per medium), or the built-in land and water scenes, with
/// each of `sets` applied to every scene that has its path's parent (the land scene's
/// objects and the water scene's alike; an effect only where it is declared), each
/// scene then checked as its file is.
///
/// # Errors
/// A scene file that does not read or validate, a set whose path is in no scene, a
/// value the scene refuses.
pub fn load_scenes(
    paths: &[std::path::PathBuf],
    sets: &[Override],
) -> Result<Vec<SceneSpec>, TrialsError> {
    let read: Vec<(SceneSpec, ConfigSource)> = if paths.is_empty() {
        [
            ("built-in land scene", LAND_TOML),
            ("built-in water scene", WATER_TOML),
        ]
        .iter()
        .map(|(name, text)| {
            let source = ConfigSource::Embedded(name);
            parse_toml::<SceneSpec>(text, &source)
                .map(|s| (s, source))
                .map_err(|e| TrialsError::Failed(e.to_string()))
        })
        .collect::<Result<_, _>>()?
    } else {
        paths
            .iter()
            .map(|p| {
                let r = softtouch_collector::configs::resolve(None, Some(p))?;
                Ok((r.scene, r.scene_source))
            })
            .collect::<Result<_, TrialsError>>()?
    };
    // The medium is a label the tables group by; the physics are the effects a scene
    // declares. A set medium would relabel trials whose physics it does not change.
    if let Some(o) = sets.iter().find(|o| o.path == "medium") {
        return Err(invalid(format!(
            "--set {o}: the medium only labels a scene (its physics are the effects it declares); choose a scene of that medium instead (--scene water, --scene grasp-water or a file)"
        )));
    }
    let mut scenes = Vec::with_capacity(read.len());
    for (mut scene, source) in read {
        let here: Vec<Override> = sets
            .iter()
            .filter(|o| overrides::applies_to(&scene, &o.path))
            .cloned()
            .collect();
        if !here.is_empty() {
            scene = overrides::apply(&scene, &here, &source)?;
        }
        scenes.push(scene);
    }
    for o in sets {
        in_some_scene(&scenes, &o.path, &format!("--set {o}"))?;
    }
    Ok(scenes)
}

/// Refuses `--set` and `--sweep` on one path: the sweep sets the value at each of its
/// values, so the `--set` would never apply, and the scenes it was applied to would
/// report it as the value they ship with.
///
/// # Errors
/// A `--set` whose path the sweep sweeps, named with both flags.
pub fn set_and_sweep_apart(sets: &[Override], sweep: Option<&Sweep>) -> Result<(), TrialsError> {
    let Some(sweep) = sweep else {
        return Ok(());
    };
    match sets.iter().find(|o| o.path == sweep.path) {
        Some(o) => Err(invalid(format!(
            "--set {o} and --sweep {}: the sweep sets `{}` at each of its values, so the --set would never apply; leave one out",
            sweep.path, sweep.path
        ))),
        None => Ok(()),
    }
}

/// Refuses a path that no scene has (its parent table), naming the scenes.
pub(super) fn in_some_scene(
    scenes: &[SceneSpec],
    path: &str,
    flag: &str,
) -> Result<(), TrialsError> {
    if scenes.iter().any(|s| overrides::applies_to(s, path)) {
        return Ok(());
    }
    // The first scene's own words on where the path went astray.
    let why = scenes
        .first()
        .and_then(|s| overrides::astray(s, path))
        .unwrap_or_default();
    Err(invalid(format!(
        "{flag}: no scene has `{path}` (scenes: {}){}",
        scenes
            .iter()
            .map(|s| format!("`{}`", s.name))
            .collect::<Vec<_>>()
            .join(", "),
        if why.is_empty() {
            String::new()
        } else {
            format!("; {why}")
        }
    )))
}

/// The base scenes (one per medium) at each of `sweep`'s values in turn, and the
/// sweep as the plan stores it. A base scene without the path's parent (the land scene
/// for a water effect) runs unchanged at every value: the same trials again.
///
/// # Errors
/// A path in no scene, a value a scene refuses (named with the value).
pub fn swept_scenes(
    base: &[SceneSpec],
    sweep: &Sweep,
) -> Result<(Vec<SceneSpec>, SceneSweep), TrialsError> {
    if sweep.path == "medium" {
        return Err(invalid(format!(
            "--sweep {}: the medium only labels a scene (its physics are the effects it declares); give the scenes of each medium with --scene instead",
            sweep.path
        )));
    }
    in_some_scene(base, &sweep.path, &format!("--sweep {}", sweep.path))?;
    let mut out = Vec::with_capacity(base.len() * sweep.values.len());
    for i in 0..sweep.values.len() {
        let Some(o) = sweep.at(i) else { continue };
        for scene in base {
            out.push(if overrides::applies_to(scene, &o.path) {
                overrides::apply(
                    scene,
                    std::slice::from_ref(&o),
                    &ConfigSource::Embedded("scene"),
                )
                .map_err(|e| {
                    invalid(format!(
                        "--sweep {}: scene `{}` at {}: {e}",
                        sweep.path,
                        scene.name,
                        overrides::shown(&o.value)
                    ))
                })?
            } else {
                scene.clone()
            });
        }
    }
    let per_value =
        u32::try_from(base.len()).map_err(|_| invalid("--scene: too many scenes".into()))?;
    // The value the scenes ship with, where those that have the path agree on one.
    let mut shipped: Vec<String> = base
        .iter()
        .filter_map(|s| overrides::value_at(s, &sweep.path))
        .map(|v| overrides::shown(&v))
        .collect();
    shipped.dedup();
    Ok((
        out,
        SceneSweep {
            path: sweep.path.clone(),
            values: sweep.values.iter().map(overrides::shown).collect(),
            per_value,
            shipped: match shipped.as_slice() {
                [one] => Some(one.clone()),
                _ => None,
            },
        },
    ))
}

/// The objects of the plan in every scene, checked: known, and inside the stroke.
pub fn objects_of(
    plan: &TrialPlan,
    scenes: &[SceneSpec],
) -> Result<Vec<Vec<GraspObject>>, TrialsError> {
    scenes
        .iter()
        .map(|scene| {
            let known: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
            if known.is_empty() {
                return Err(invalid(format!(
                    "scene `{}` declares no [[objects]]: expected the objects to grasp",
                    scene.name
                )));
            }
            plan.objects
                .iter()
                .map(|name| {
                    let spec = scene.object(name).ok_or_else(|| {
                        invalid(format!(
                            "--objects: scene `{}` declares no object `{name}` (it has: {})",
                            scene.name,
                            known.join(", ")
                        ))
                    })?;
                    let object = GraspObject::from_spec(spec);
                    let widest_mm = object.max_width_m() * 1000.0;
                    let grasp_mm = plan
                        .open_width_mm
                        .unwrap_or(object.grasp_width_m * 1000.0);
                    if widest_mm >= STROKE_MM || grasp_mm >= STROKE_MM {
                        return Err(invalid(format!(
                            "object `{name}` of scene `{}` is {widest_mm:.1} mm at its widest (open-loop width {grasp_mm:.1} mm): outside the Hand-E's {STROKE_MM} mm stroke; objects inside it: {}",
                            scene.name,
                            scene
                                .objects
                                .iter()
                                .filter(|o| GraspObject::from_spec(o).max_width_m() * 1000.0 < STROKE_MM)
                                .map(|o| o.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )));
                    }
                    Ok(object)
                })
                .collect()
        })
        .collect()
}
