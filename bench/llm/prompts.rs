//! The chats both sides are given: a fixed system prompt and a long user text for the fresh-prompt runs, and a
//! fixed conversation whose last user message alone changes for the warm-cache runs (what the agent sends each turn).

use crate::wire::ChatMessage;

/// First words of the system prompt, one per fresh run: a prompt that differs from the previous one at its first
/// word of content leaves a prefix cache only the chat template's opening tokens to reuse.
const NAMES: [&str; 24] = [
    "Alma", "Bruno", "Carla", "Dario", "Elena", "Fabio", "Giulia", "Hugo", "Irene", "Jonas",
    "Karin", "Luca", "Marta", "Nico", "Olga", "Paolo", "Rita", "Sven", "Tina", "Ugo", "Vera",
    "Walter", "Xenia", "Yuri",
];

/// The system prompt after the name.
const SYSTEM: &str = "is a friendly robot that lives in a small science museum. It answers visitors in plain, \
complete sentences, keeps a warm and patient tone, never invents facts it is unsure of, and when a visitor shares a \
long text it retells the text carefully, keeping the order of the events and the names of the people in it.";

/// The long user text, cycled sentence by sentence until it holds the words a prompt size asks for.
const STORY: [&str; 12] = [
    "Early on a grey Monday morning the museum opened its doors to a class of thirty children and their two teachers.",
    "The children had travelled by train from a village in the hills, and most of them had never seen a robot before.",
    "In the first hall they found a steam engine that still worked, and a guide showed them how the pistons moved.",
    "A girl called Nora asked why the engine needed so much water, and the guide explained how steam pushes a piston.",
    "In the second hall a tall pendulum swung slowly over a ring of wooden pegs, knocking one down every few minutes.",
    "The teachers told the children that the pendulum proved the Earth turns, and the children waited to see a peg fall.",
    "After lunch in the garden the class met the museum robot, which greeted each child by the colour of their coat.",
    "A boy called Marco asked the robot whether it ever slept, and the robot said that it rested its motors at night.",
    "The robot then led the children to a dark room where the ceiling showed the stars as they look from the hills.",
    "Nora found the constellation her grandmother had taught her, and she pointed it out to the rest of the class.",
    "Before leaving, every child drew a picture of the part of the visit they liked best and pinned it on a board.",
    "On the train home the teachers counted the drawings and saw that the robot and the pendulum had won by far.",
];

/// What the user asks about the story: a retelling runs past the token limit, so both sides generate all of it.
const ASK: &str =
    "Please retell the following story in your own words, in detail, from beginning to end.";

/// Prompt sizes the fresh runs use, as (the nominal token count, words of story that give about that many tokens
/// with SmolLM2's tokenizer and ChatML template; the real counts are reported by each side).
pub const SIZES: [(u32, usize); 2] = [(200, 80), (800, 620)];

/// A fresh chat of about `words` words of story, whose system prompt starts with the `run`-th name.
pub fn fresh(words: usize, run: usize) -> Vec<ChatMessage> {
    let mut story = String::new();
    let mut count = 0;
    for sentence in STORY.iter().cycle() {
        if count >= words {
            break;
        }
        if !story.is_empty() {
            story.push(' ');
        }
        story.push_str(sentence);
        count += sentence.split_whitespace().count();
    }
    vec![
        ChatMessage::system(format!("{} {SYSTEM}", NAMES[run % NAMES.len()])),
        ChatMessage::user(format!("{ASK}\n\n{story}")),
    ]
}

/// Last user messages of the warm-cache runs; the first one primes the cache and is not timed.
pub const QUESTIONS: [&str; 12] = [
    "What did you like most about today?",
    "Can you tell me a short joke about robots?",
    "Why does a pendulum keep swinging?",
    "How far away is the nearest star?",
    "What should I draw for my picture?",
    "Do robots ever get tired of talking?",
    "Which hall should we visit first tomorrow?",
    "How does a steam engine use water?",
    "What is your favourite constellation?",
    "Can you say goodbye to my little brother?",
    "Is the museum open on Sundays?",
    "What makes the sky look dark at night?",
];

/// The agent's turn with the cache warm: the same system prompt and history every time, `question` last.
pub fn conversation(question: &str) -> Vec<ChatMessage> {
    vec![
        ChatMessage::system(format!("Robo {SYSTEM}")),
        ChatMessage::user(STORY[..4].join(" ")),
        ChatMessage::assistant(
            "What a lovely morning! The class came by train from the hills, saw the old steam engine working, and \
             Nora learned that steam pushes the piston.",
        ),
        ChatMessage::user(STORY[4..8].join(" ")),
        ChatMessage::assistant(
            "The pendulum shows that the Earth turns, and I was glad to meet Marco. I do rest my motors at night.",
        ),
        ChatMessage::user(question.to_owned()),
    ]
}
