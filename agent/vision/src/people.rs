//! People in view: the faces the detector found, followed from frame to frame and analysed with `agent-face`
//! (landmarks every frame, an identity descriptor now and then), with who is talking (`speaker.rs`) and the names
//! of the faces the agent was introduced to.
//!
//! Cost is bounded per frame: landmarks for at most `max_faces` faces (the largest; about 5 ms each) and at most one
//! descriptor (about 15 ms), for a face turned to the camera that has none yet or whose last one is older than
//! `describe_every_us`.

use agent_face::{
    Acquaintance, Descriptor, FaceAnalyzer, FaceBox, FaceMeasures, FaceModelPaths, GreyImage,
    measure, recognise,
};
use opencv::core::MatTraitConstManual;

use crate::error::VisionError;
use crate::frame::GreyFrame;
use crate::geometry::BoxPx;
use crate::speaker::{MouthHistory, SpeakerChoice, SpeakerParams};

/// Tuning of the analysis.
#[derive(Debug, Clone, PartialEq)]
pub struct PeopleParams {
    pub models: FaceModelPaths,
    /// The largest faces analysed per frame; the others are boxes only.
    pub max_faces: usize,
    /// A face's descriptor is computed again after this long (lighting and pose change).
    pub describe_every_us: u64,
    /// A face not seen for this long has left: its next appearance is a new person.
    pub forget_after_us: u64,
    /// Descriptors closer than this are the same person.
    pub match_distance: f32,
    pub speaker: SpeakerParams,
}

impl Default for PeopleParams {
    fn default() -> Self {
        Self {
            models: FaceModelPaths::default(),
            max_faces: 4,
            describe_every_us: 2_000_000,
            forget_after_us: 1_000_000,
            match_distance: MATCH_DISTANCE,
            speaker: SpeakerParams::default(),
        }
    }
}

/// One analysed face of a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Person {
    pub id: u64,
    pub face: BoxPx,
    pub measures: FaceMeasures,
    pub speaking: bool,
    pub name: Option<String>,
}

/// A face followed across frames.
#[derive(Debug)]
struct Track {
    id: u64,
    face: BoxPx,
    last_seen_us: u64,
    mouth: MouthHistory,
    descriptor: Option<Descriptor>,
    described_us: Option<u64>,
    name: Option<String>,
}

/// The analysis with its state across frames.
#[derive(Debug)]
pub struct People {
    params: PeopleParams,
    analyzer: FaceAnalyzer,
    tracks: Vec<Track>,
    next_id: u64,
    known: Vec<Acquaintance>,
    speaker: SpeakerChoice,
    /// The last face that was talking, and when (frame time): whom `learn_face` means.
    last_speaker: Option<(u64, u64)>,
    last_frame_us: u64,
    descriptors_computed: u64,
}

/// Descriptors closer than this are one person. dlib's 0.6 (set on colour photos of Labeled Faces in the Wild) let
/// 9.3% of the pairs of different people on the fixtures' grey faces match; 0.45 lets about 1%, and the one man
/// photographed twice there is at 0.37 (`vision-people-bench`).
pub const MATCH_DISTANCE: f32 = 0.45;

/// How long after talking a person is still the one `learn_face` means (the transcript comes after the speech).
const LEARN_WITHIN_US: u64 = 10_000_000;

impl People {
    /// Loads the models (a missing or broken file fails naming it and `make model-face`).
    pub fn new(params: PeopleParams) -> Result<Self, VisionError> {
        let analyzer = FaceAnalyzer::load(&params.models)?;
        Ok(Self {
            speaker: SpeakerChoice::new(params.speaker.clone()),
            params,
            analyzer,
            tracks: Vec::new(),
            next_id: 1,
            known: Vec::new(),
            last_speaker: None,
            last_frame_us: 0,
            descriptors_computed: 0,
        })
    }

    /// Whether a voice is heard now.
    pub fn set_voice(&mut self, active: bool) {
        self.speaker.set_voice(active);
    }

    /// The people the agent knows; faces already described are named again at once.
    pub fn set_known(&mut self, known: Vec<Acquaintance>) {
        self.known = known;
        for track in &mut self.tracks {
            track.name = track.descriptor.as_ref().and_then(|d| {
                recognise(d, &self.known, self.params.match_distance).map(|(p, _)| p.name.clone())
            });
        }
    }

    /// Descriptors computed since the start (for status and tests).
    pub fn descriptors_computed(&self) -> u64 {
        self.descriptors_computed
    }

    /// The face `learn_face` means, with its descriptor: the last one talking (within ten seconds, still in view),
    /// else the only face in view. `None` when it is ambiguous or the face has no descriptor yet.
    pub fn learnable(&self) -> Option<(u64, Descriptor)> {
        let recent_speaker = self.last_speaker.and_then(|(id, at)| {
            (self.last_frame_us.saturating_sub(at) <= LEARN_WITHIN_US).then_some(id)
        });
        let track = match recent_speaker {
            Some(id) => self.tracks.iter().find(|t| t.id == id),
            None if self.tracks.len() == 1 => self.tracks.first(),
            None => None,
        }?;
        Some((track.id, track.descriptor.clone()?))
    }

    /// Forgets the faces followed (a new stream).
    pub fn reset(&mut self) {
        self.tracks.clear();
        self.speaker = SpeakerChoice::new(self.params.speaker.clone());
        self.last_speaker = None;
    }

    /// Analyses the faces of one frame; a descriptor that is due is computed only when `may_describe`.
    pub fn observe(
        &mut self,
        frame: &GreyFrame,
        frame_us: u64,
        faces: &[BoxPx],
        may_describe: bool,
    ) -> Result<Vec<Person>, VisionError> {
        if frame_us < self.last_frame_us {
            self.reset();
        }
        self.last_frame_us = frame_us;
        let mat = frame.mat();
        let size = frame.size();
        let pixels = mat.data_bytes()?;
        let image = GreyImage::new(pixels, size.width, size.height, size.width)?;

        let mut largest: Vec<BoxPx> = faces.to_vec();
        largest.sort_by_key(|f| std::cmp::Reverse(f.area()));
        largest.truncate(self.params.max_faces);

        let forget = self.params.forget_after_us;
        self.tracks
            .retain(|t| frame_us.saturating_sub(t.last_seen_us) <= forget);
        let mut seen: Vec<(usize, FaceMeasures, agent_face::Landmarks)> = Vec::new();
        for face in largest {
            let index = self.track_for(face, frame_us, &seen);
            let points = self.analyzer.landmarks(&image, FaceBox::from(face))?;
            let Some(measures) = measure(&points) else {
                continue;
            };
            let window = self.params.speaker.window_us;
            let track = &mut self.tracks[index];
            track.mouth.push(frame_us, measures.mouth_open, window);
            seen.push((index, measures, points));
        }
        if may_describe {
            self.describe_one(&image, frame_us, &seen)?;
        }

        let movements: Vec<(u64, f32)> = seen
            .iter()
            .map(|(i, _, _)| (self.tracks[*i].id, self.tracks[*i].mouth.movement()))
            .collect();
        let speaker = self.speaker.update(frame_us, &movements);
        if let Some(id) = speaker {
            self.last_speaker = Some((id, frame_us));
        }
        Ok(seen
            .iter()
            .map(|(i, measures, _)| {
                let track = &self.tracks[*i];
                Person {
                    id: track.id,
                    face: track.face,
                    measures: *measures,
                    speaking: speaker == Some(track.id),
                    name: track.name.clone(),
                }
            })
            .collect())
    }

    /// The track `face` continues (the one it overlaps most, not already taken this frame), or a new one.
    fn track_for(
        &mut self,
        face: BoxPx,
        frame_us: u64,
        taken: &[(usize, FaceMeasures, agent_face::Landmarks)],
    ) -> usize {
        let best = self
            .tracks
            .iter()
            .enumerate()
            .filter(|(i, _)| !taken.iter().any(|(t, _, _)| t == i))
            .map(|(i, t)| (i, t.face.iou(&face)))
            .filter(|&(_, iou)| iou > 0.3)
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i);
        let index = best.unwrap_or_else(|| {
            self.tracks.push(Track {
                id: self.next_id,
                face,
                last_seen_us: frame_us,
                mouth: MouthHistory::default(),
                descriptor: None,
                described_us: None,
                name: None,
            });
            self.next_id += 1;
            self.tracks.len() - 1
        });
        let track = &mut self.tracks[index];
        track.face = face;
        track.last_seen_us = frame_us;
        index
    }

    /// Computes the descriptor of the face that most needs one: faces turned to the camera without one first (the
    /// largest), then the one described longest ago past `describe_every_us`.
    fn describe_one(
        &mut self,
        image: &GreyImage<'_>,
        frame_us: u64,
        seen: &[(usize, FaceMeasures, agent_face::Landmarks)],
    ) -> Result<(), VisionError> {
        if !self.analyzer.has_descriptors() {
            return Ok(());
        }
        let due = seen
            .iter()
            .filter(|(_, measures, _)| measures.looking())
            .filter_map(|(i, _, points)| {
                let track = &self.tracks[*i];
                match track.described_us {
                    None => Some((0, *i, points)),
                    Some(at) if frame_us.saturating_sub(at) >= self.params.describe_every_us => {
                        Some((at.max(1), *i, points))
                    }
                    Some(_) => None,
                }
            })
            .min_by_key(|&(at, _, _)| at);
        let Some((_, index, points)) = due else {
            return Ok(());
        };
        let descriptor = self.analyzer.descriptor(image, points)?;
        self.descriptors_computed += 1;
        let name = recognise(&descriptor, &self.known, self.params.match_distance)
            .map(|(p, _)| p.name.clone());
        let track = &mut self.tracks[index];
        track.descriptor = Some(descriptor);
        track.described_us = Some(frame_us);
        track.name = name;
        Ok(())
    }
}
