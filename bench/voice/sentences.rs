//! What voice-bench's engines say for the intelligibility figure: numbers, names, questions and the agent's own
//! replies from config/brain.tr.

/// Forty English sentences, each both what the engine reads and the reference whisper's transcript is scored
/// against (numbers are in digits, as whisper writes them).
pub const INTELLIGIBILITY: [&str; 40] = [
    // The agent's own replies (config/brain.tr).
    "Hello! How can I help you?",
    "You're welcome.",
    "I am the robot agent. I can see, listen and talk.",
    "Let me check.",
    "Sorry, I did not understand. You can ask me the time, or what I see.",
    "I can see two people in front of me.",
    "I can't see anyone right now.",
    "Nobody is here, but something is moving on the left.",
    "I don't see any code. Hold it up to the camera, please.",
    "I haven't said anything yet.",
    "Good afternoon! Nice to see you. Ask me anything.",
    "It is a quarter past three.",
    // Numbers, in digits: the engines read them as words and whisper writes them as digits.
    "The meeting starts at 9 in room 12.",
    "There are 47 boxes on the third shelf.",
    "The train leaves in 20 minutes from platform 6.",
    "It costs 19 dollars.",
    "We counted 160 birds this morning.",
    "The temperature dropped to 4 degrees last night.",
    "Turn left after the second traffic light.",
    "I was born in 1985.",
    // Names.
    "Maria and John are coming to dinner on Friday.",
    "Please call Doctor Robinson before noon.",
    "Anna lives in London with her brother Peter.",
    "The letter was signed by Thomas Edison.",
    "Ask Michael whether the package arrived in Chicago.",
    "Sarah bought a new bicycle in Amsterdam.",
    "David and Emma met at the library in Boston.",
    "Captain Miller checked the map once more.",
    // Questions.
    "What time is it?",
    "Where did you leave the keys?",
    "Can you read the code on this card?",
    "How many people are in the room?",
    "Would you like a cup of tea or coffee?",
    "Why is the sky blue during the day?",
    "Is the door on the left open?",
    "Who wrote this message on the board?",
    // Longer sentences.
    "The quick brown fox jumps over the lazy dog near the river bank.",
    "Please remember to water the plants while I am away next week.",
    "The robot turned its head and looked at the visitor with interest.",
    "After the rain stopped, the children went outside to play football.",
];
