//! The vision module's settings as written in the configuration (`[modules.vision]` and its sub-tables), parsed
//! from the module's JSON parameters and checked before anything starts. Unknown keys are errors, so a typo
//! fails at start instead of being silently ignored.

use agent_contract::channels;
use std::path::PathBuf;

use serde::Deserialize;

use crate::centerface::CenterFaceParams;
use crate::codes::CodeParams;
use crate::error::VisionError;
use crate::face::{Cascade, DEBIAN_CASCADE_DIR, FaceParams};
use crate::frame::DEFAULT_MAX_PIXELS;
use crate::gaze::GazeParams;
use crate::motion::{MotionMethod, MotionParams};
use crate::people_settings::PeopleSettings;
use crate::pipeline::{FaceDetection, PipelineParams};
use crate::setting_check::{check, invalid};

/// `[modules.vision]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VisionSettings {
    /// Read by the server to switch the module off.
    pub enabled: bool,
    /// The camera channel to process: `Agent.video` (colour JPEG, decoded straight to grey) or `Agent.video.y`.
    pub source: String,
    /// Also publish the gaze target as a `gaze` command on `Agent.avatar` (only when no other module owns that
    /// channel; the behaviour controller otherwise takes the target from `Agent.detections`).
    pub avatar_gaze: bool,
    pub max_frame_pixels: u64,
    /// Threads OpenCV may use inside one call (process-wide).
    pub threads: u32,
    pub faces: FaceSettings,
    /// `[modules.vision.people]`: the per-face analysis of the faces found.
    pub people: PeopleSettings,
    pub motion: MotionSettings,
    pub codes: CodeSettings,
    pub gaze: GazeSettings,
}

/// `[modules.vision.faces]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaceSettings {
    pub enabled: bool,
    /// `centerface` (the network, the default) or `cascades` (OpenCV's cascades with the budgeted scan, tuned by
    /// the keys below).
    pub detector: String,
    /// `[modules.vision.faces.centerface]`: the network's settings, parsed straight into its parameters.
    pub centerface: CenterFaceParams,
    /// `haar_default`, `haar_alt`, `haar_alt2`, `lbp`, `lbp_improved`.
    pub cascade: String,
    pub cascade_dir: PathBuf,
    pub scale_factor: f64,
    pub min_neighbors: i32,
    pub min_face_px: u32,
    pub max_detect_width: u32,
    pub equalize: bool,
    /// Pixels scanned per frame; 0 scans the whole pyramid on every frame.
    pub scan_budget_px: u64,
    /// The cascade that must confirm each candidate (one of the cascade names), or `none`.
    pub verify: String,
    /// A further cascade whose confirmation also counts, or `none`.
    pub verify_also: String,
    /// Pyramids of the budgeted cycle, each shifted by a fraction of the scale step (1-4).
    pub pyramid_phases: u32,
    /// Scan regions where motion appears first, at every face size (needs the motion detector).
    pub motion_focus: bool,
    /// `min_neighbors` of those focus scans.
    pub focus_min_neighbors: i32,
}

/// `[modules.vision.motion]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionSettings {
    pub enabled: bool,
    /// `difference` or `mog2`.
    pub method: String,
    pub work_width: u32,
    pub pixel_threshold: f64,
    pub on_fraction: f64,
    pub min_region_fraction: f64,
    pub hold_ms: u64,
    pub mog2_warmup_frames: u32,
}

/// `[modules.vision.codes]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CodeSettings {
    pub enabled: bool,
    pub qr: bool,
    pub barcodes: bool,
    /// A code unseen for this long has left; its next sighting is reported again.
    pub forget_after_ms: u64,
}

/// `[modules.vision.gaze]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GazeSettings {
    pub smoothing_ms: u64,
    pub switch_margin: f32,
    pub deadband: f32,
    pub hold_ms: u64,
}

impl Default for VisionSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            source: channels::VIDEO.name.to_owned(),
            avatar_gaze: false,
            max_frame_pixels: DEFAULT_MAX_PIXELS,
            threads: 1,
            faces: FaceSettings::default(),
            people: PeopleSettings::default(),
            motion: MotionSettings::default(),
            codes: CodeSettings::default(),
            gaze: GazeSettings::default(),
        }
    }
}

impl Default for FaceSettings {
    fn default() -> Self {
        let face = FaceParams::default();
        Self {
            enabled: true,
            detector: "centerface".to_owned(),
            centerface: CenterFaceParams::default(),
            cascade: face.cascade.name().to_owned(),
            cascade_dir: PathBuf::from(DEBIAN_CASCADE_DIR),
            scale_factor: face.scale_factor,
            min_neighbors: face.min_neighbors,
            min_face_px: face.min_face_px,
            max_detect_width: face.max_detect_width,
            equalize: face.equalize,
            scan_budget_px: face.scan_budget_px.unwrap_or(0),
            verify: face.verify.map_or("none", Cascade::name).to_owned(),
            verify_also: face.verify_also.map_or("none", Cascade::name).to_owned(),
            pyramid_phases: face.pyramid_phases,
            motion_focus: face.motion_focus,
            focus_min_neighbors: face.focus_min_neighbors,
        }
    }
}

impl Default for MotionSettings {
    fn default() -> Self {
        let motion = MotionParams::default();
        Self {
            enabled: true,
            method: motion.method.name().to_owned(),
            work_width: motion.work_width,
            pixel_threshold: motion.pixel_threshold,
            on_fraction: motion.on_fraction,
            min_region_fraction: motion.min_region_fraction,
            hold_ms: motion.hold_us / 1000,
            mog2_warmup_frames: motion.mog2_warmup_frames,
        }
    }
}

impl Default for CodeSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            qr: true,
            barcodes: true,
            forget_after_ms: 1000,
        }
    }
}

impl Default for GazeSettings {
    fn default() -> Self {
        let gaze = GazeParams::default();
        Self {
            smoothing_ms: gaze.smoothing_us / 1000,
            switch_margin: gaze.switch_margin,
            deadband: gaze.deadband,
            hold_ms: gaze.hold_us / 1000,
        }
    }
}

impl VisionSettings {
    /// Parses the module's parameters; `null` or `{}` gives the defaults.
    pub fn from_json(params: &serde_json::Value) -> Result<Self, VisionError> {
        if params.is_null() {
            return Ok(Self::default());
        }
        serde_json::from_value(params.clone()).map_err(|e| invalid("modules.vision", e.to_string()))
    }

    /// Checks ranges and names and builds the detector parameters.
    pub fn pipeline_params(&self) -> Result<PipelineParams, VisionError> {
        check(
            [channels::VIDEO.name, channels::VIDEO_Y.name].contains(&self.source.as_str()),
            "source",
            "must be the camera or its grey version (Agent.video or Agent.video.y)",
        )?;
        check(
            self.max_frame_pixels >= 64 * 64,
            "max_frame_pixels",
            "must be at least 4096",
        )?;
        let faces = if !self.faces.enabled {
            None
        } else if self.faces.detector == "centerface" {
            let params = self.faces.centerface.clone();
            params.validate()?;
            Some(FaceDetection::CenterFace(params))
        } else if self.faces.detector == "cascades" {
            let f = &self.faces;
            let cascade = Cascade::from_name(&f.cascade).ok_or_else(|| {
                invalid("faces.cascade", format!("unknown cascade {:?}; one of haar_default, haar_alt, haar_alt2, lbp, lbp_improved", f.cascade))
            })?;
            check(
                f.scale_factor > 1.0 && f.scale_factor <= 2.0,
                "faces.scale_factor",
                "must be in (1, 2]",
            )?;
            check(
                (0..=50).contains(&f.min_neighbors),
                "faces.min_neighbors",
                "must be 0-50",
            )?;
            check(
                (0..=50).contains(&f.focus_min_neighbors),
                "faces.focus_min_neighbors",
                "must be 0-50",
            )?;
            check(
                (8..=1000).contains(&f.min_face_px),
                "faces.min_face_px",
                "must be 8-1000",
            )?;
            check(
                (64..=4096).contains(&f.max_detect_width),
                "faces.max_detect_width",
                "must be 64-4096",
            )?;
            check(
                f.scan_budget_px == 0 || f.scan_budget_px >= 10_000,
                "faces.scan_budget_px",
                "must be 0 (whole scan) or at least 10000",
            )?;
            let verify = match f.verify.as_str() {
                "none" => None,
                name => Some(Cascade::from_name(name).ok_or_else(|| {
                    invalid("faces.verify", format!("unknown cascade {name:?}; one of haar_default, haar_alt, haar_alt2, lbp, lbp_improved, or none"))
                })?),
            };
            let verify_also = match f.verify_also.as_str() {
                "none" => None,
                name => Some(Cascade::from_name(name).ok_or_else(|| {
                    invalid("faces.verify_also", format!("unknown cascade {name:?}; one of haar_default, haar_alt, haar_alt2, lbp, lbp_improved, or none"))
                })?),
            };
            check(
                (1..=4).contains(&f.pyramid_phases),
                "faces.pyramid_phases",
                "must be 1-4",
            )?;
            Some(FaceDetection::Cascades(FaceParams {
                verify,
                verify_also,
                pyramid_phases: f.pyramid_phases,
                cascade,
                cascade_dir: f.cascade_dir.clone(),
                scale_factor: f.scale_factor,
                min_neighbors: f.min_neighbors,
                min_face_px: f.min_face_px,
                max_detect_width: f.max_detect_width,
                equalize: f.equalize,
                scan_budget_px: (f.scan_budget_px > 0).then_some(f.scan_budget_px),
                motion_focus: f.motion_focus,
                focus_min_neighbors: f.focus_min_neighbors,
            }))
        } else {
            return Err(invalid(
                "faces.detector",
                format!(
                    "unknown detector {:?}; centerface or cascades",
                    self.faces.detector
                ),
            ));
        };
        let motion = if self.motion.enabled {
            let m = &self.motion;
            let method = MotionMethod::from_name(&m.method).ok_or_else(|| {
                invalid(
                    "motion.method",
                    format!("unknown method {:?}; difference or mog2", m.method),
                )
            })?;
            check(
                (32..=1920).contains(&m.work_width),
                "motion.work_width",
                "must be 32-1920",
            )?;
            check(
                m.pixel_threshold > 0.0 && m.pixel_threshold < 255.0,
                "motion.pixel_threshold",
                "must be in (0, 255)",
            )?;
            check(
                m.on_fraction > 0.0 && m.on_fraction < 1.0,
                "motion.on_fraction",
                "must be in (0, 1)",
            )?;
            check(
                (0.0..1.0).contains(&m.min_region_fraction),
                "motion.min_region_fraction",
                "must be in [0, 1)",
            )?;
            check(
                m.hold_ms <= 10_000,
                "motion.hold_ms",
                "must be at most 10000",
            )?;
            Some(MotionParams {
                method,
                work_width: m.work_width,
                pixel_threshold: m.pixel_threshold,
                on_fraction: m.on_fraction,
                min_region_fraction: m.min_region_fraction,
                hold_us: m.hold_ms * 1000,
                mog2_warmup_frames: m.mog2_warmup_frames,
            })
        } else {
            None
        };
        let codes = if self.codes.enabled {
            check(
                self.codes.qr || self.codes.barcodes,
                "codes",
                "enabled with neither qr nor barcodes",
            )?;
            Some(CodeParams {
                qr: self.codes.qr,
                barcodes: self.codes.barcodes,
            })
        } else {
            None
        };
        let g = &self.gaze;
        check(
            g.switch_margin >= 1.0,
            "gaze.switch_margin",
            "must be at least 1",
        )?;
        check(
            (0.0..0.5).contains(&g.deadband),
            "gaze.deadband",
            "must be in [0, 0.5)",
        )?;
        let people = if faces.is_some() {
            self.people.params()?
        } else {
            None
        };
        Ok(PipelineParams {
            faces,
            people,
            motion,
            codes,
            code_forget_after_us: self.codes.forget_after_ms * 1000,
            gaze: GazeParams {
                smoothing_us: g.smoothing_ms * 1000,
                switch_margin: g.switch_margin,
                deadband: g.deadband,
                hold_us: g.hold_ms * 1000,
            },
            max_frame_pixels: self.max_frame_pixels,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn empty_params_give_defaults() {
        let settings = VisionSettings::from_json(&json!({})).expect("defaults");
        let params = settings.pipeline_params().expect("valid");
        assert!(params.faces.is_some() && params.motion.is_some() && params.codes.is_some());
        assert_eq!(settings.source, channels::VIDEO.name);
    }

    #[test]
    fn unknown_key_is_named() {
        let err =
            VisionSettings::from_json(&json!({"faces": {"cascde": "lbp"}})).expect_err("typo");
        assert!(err.to_string().contains("cascde"), "{err}");
    }

    #[test]
    fn bad_values_name_their_key() {
        let settings = VisionSettings::from_json(
            &json!({"faces": {"detector": "cascades", "cascade": "eyes"}}),
        )
        .expect("parses");
        let err = settings.pipeline_params().expect_err("unknown cascade");
        assert!(err.to_string().contains("faces.cascade"), "{err}");
        let settings =
            VisionSettings::from_json(&json!({"motion": {"method": "optical"}})).expect("parses");
        assert!(
            settings
                .pipeline_params()
                .expect_err("bad method")
                .to_string()
                .contains("motion.method")
        );
        let settings = VisionSettings::from_json(
            &json!({"faces": {"detector": "cascades", "focus_min_neighbors": 51}}),
        )
        .expect("parses");
        let err = settings.pipeline_params().expect_err("too many neighbours");
        assert!(
            err.to_string().contains("faces.focus_min_neighbors"),
            "{err}"
        );
    }

    #[test]
    fn the_face_detector_is_chosen_by_name() {
        let params = VisionSettings::default().pipeline_params().expect("valid");
        assert!(matches!(params.faces, Some(FaceDetection::CenterFace(_))));
        let settings =
            VisionSettings::from_json(&json!({"faces": {"detector": "cascades"}})).expect("parses");
        let params = settings.pipeline_params().expect("valid");
        assert!(matches!(params.faces, Some(FaceDetection::Cascades(_))));
        let settings =
            VisionSettings::from_json(&json!({"faces": {"detector": "yolo"}})).expect("parses");
        let err = settings.pipeline_params().expect_err("unknown detector");
        assert!(err.to_string().contains("faces.detector"), "{err}");
        let settings =
            VisionSettings::from_json(&json!({"faces": {"centerface": {"input_width": 300}}}))
                .expect("parses");
        let err = settings
            .pipeline_params()
            .expect_err("not a multiple of 32");
        assert!(
            err.to_string().contains("faces.centerface.input_width"),
            "{err}"
        );
    }

    #[test]
    fn switches_turn_detectors_off() {
        let settings = VisionSettings::from_json(
            &json!({"faces": {"enabled": false}, "codes": {"enabled": false}}),
        )
        .expect("parses");
        let params = settings.pipeline_params().expect("valid");
        assert!(params.faces.is_none() && params.codes.is_none() && params.motion.is_some());
    }
}
