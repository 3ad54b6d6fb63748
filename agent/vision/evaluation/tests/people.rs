//! The per-face analysis through the pipeline the vision module runs, on the generated two-person clip
//! (`vision_evaluation::talking`): who is talking follows the mouth that moves while a voice is heard, and the
//! gaze goes to them. Counted in frames, so the test does not depend on the machine's speed.

use agent_vision::gaze::GazeSource;
use agent_vision::{PipelineParams, VisionPipeline};
use vision_evaluation::fixtures::fixtures_dir;
use vision_evaluation::talking::{Side, talking_pair};

/// 15 fps frames per turn: three seconds.
const TURN: usize = 45;

fn side_of(x: f32) -> Side {
    if x < 320.0 { Side::Left } else { Side::Right }
}

#[test]
fn the_speaker_is_the_moving_mouth_and_the_gaze_follows_the_turns() {
    let turns = [
        None,
        Some(Side::Left),
        Some(Side::Right),
        Some(Side::Left),
        None,
    ];
    let clip = talking_pair(&fixtures_dir(), &turns, TURN).expect("clip");
    let mut pipeline = VisionPipeline::new(PipelineParams::default()).expect("pipeline");
    let (mut voiced, mut right, mut silent_named) = (0, 0, 0);
    let mut gaze_turned_after: Vec<Option<usize>> = vec![None; turns.len()];
    for (i, frame) in clip.iter().enumerate() {
        pipeline
            .people()
            .expect("the analysis runs by default")
            .set_voice(frame.speaker.is_some());
        let d = pipeline
            .process_jpeg(&frame.jpeg, i as u64 + 1, frame.frame_us)
            .expect("frame");
        let people = d.people.expect("people");
        let speaking: Vec<Side> = people
            .iter()
            .filter(|p| p.speaking)
            .map(|p| side_of(p.face.centre().x))
            .collect();
        assert!(speaking.len() <= 1, "frame {i}: {speaking:?}");
        let turn = i / TURN;
        match frame.speaker {
            Some(side) => {
                voiced += 1;
                if speaking == [side] {
                    right += 1;
                }
                let gaze_side = if d.gaze.x < 0.5 {
                    Side::Left
                } else {
                    Side::Right
                };
                if d.gaze.source == GazeSource::Face
                    && gaze_side == side
                    && gaze_turned_after[turn].is_none()
                {
                    gaze_turned_after[turn] = Some(i % TURN);
                }
            }
            // The first second of silence names nobody; after a turn the speaker is held for a moment only.
            None if i % TURN > 12 && !speaking.is_empty() => silent_named += 1,
            None => {}
        }
    }
    let share = f64::from(right) / f64::from(voiced);
    eprintln!(
        "speaker right in {right} of {voiced} voiced frames ({share:.3}); gaze on the speaker after {gaze_turned_after:?} frames; {silent_named} silent frames with a speaker"
    );
    assert!(share >= 0.85, "{share}");
    assert_eq!(silent_named, 0);
    // The turns after the first begin with the gaze on the other person: it must come over within 8 frames
    // (533 ms at 15 fps).
    for (turn, after) in gaze_turned_after.iter().enumerate().take(4).skip(2) {
        let after = after.expect("the gaze never reached the speaker");
        assert!(after <= 8, "turn {turn}: {after} frames");
    }
}
