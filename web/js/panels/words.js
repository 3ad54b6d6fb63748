// @ts-check
//! The page's own words (controls, labels, states) in each language the agent speaks, and the choice of one: the
//! agent's language from the welcome (`agent.language`), unless `?lang=` asks for another. Pure: no DOM here.

/** @typedef {"en" | "it"} Language */

/** The words, by key; `{name}` marks a value filled in by `fill`. */
export const WORDS = {
  en: {
    camera: "Camera",
    cameraOff: "off",
    previewEmpty: "camera off",
    startMicrophone: "Start microphone",
    stopMicrophone: "Stop microphone",
    startCamera: "Start camera",
    stopCamera: "Stop camera",
    agent: "Agent",
    agentMeta: "speaks through Agent.ctrl",
    holderMeta: "you are talking to the agent",
    notHolderMeta: "only while you hold the microphone",
    listeningOn: "Listening: on",
    listeningOff: "Listening: off",
    hush: "Stop speaking",
    record: "Record",
    recordTitle: "record the session into an MCAP file (opens in Foxglove)",
    stopRecording: "Stop recording",
    notRecording: "not recording",
    recordingTo: "● recording {name}",
    saved: "saved {name} ({messages} messages)",
    sayPlaceholder: "Type something for the agent to say",
    say: "Say",
    spectrum: "Microphone spectrum",
    rules: "Rule trace",
  },
  it: {
    camera: "Videocamera",
    cameraOff: "spenta",
    previewEmpty: "videocamera spenta",
    startMicrophone: "Accendi il microfono",
    stopMicrophone: "Spegni il microfono",
    startCamera: "Accendi la videocamera",
    stopCamera: "Spegni la videocamera",
    agent: "Agente",
    agentMeta: "parla attraverso Agent.ctrl",
    holderMeta: "stai parlando con l'agente",
    notHolderMeta: "solo mentre hai il microfono",
    listeningOn: "Ascolto: attivo",
    listeningOff: "Ascolto: spento",
    hush: "Smetti di parlare",
    record: "Registra",
    recordTitle: "registra la sessione in un file MCAP (si apre in Foxglove)",
    stopRecording: "Ferma la registrazione",
    notRecording: "non in registrazione",
    recordingTo: "● registrazione di {name}",
    saved: "salvato {name} ({messages} messaggi)",
    sayPlaceholder: "Scrivi qualcosa da far dire all'agente",
    say: "Di'",
    spectrum: "Spettro del microfono",
    rules: "Traccia delle regole",
  },
};

/** @typedef {keyof typeof WORDS.en} WordKey */

/**
 * The language to show: `?lang=` when it names one the page knows, else the agent's, else English.
 * @param {string | null | undefined} asked the `lang` query parameter
 * @param {string | null | undefined} agent the welcome's `language`
 * @returns {Language}
 */
export function pickLanguage(asked, agent) {
  for (const candidate of [asked, agent]) {
    if (candidate === "en" || candidate === "it") return candidate;
  }
  return "en";
}

/**
 * The words of `language`.
 * @param {Language} language
 * @returns {Record<WordKey, string>}
 */
export function wordsFor(language) {
  return WORDS[language];
}

/**
 * `template` with each `{name}` replaced by `values[name]` (left as it is when there is no such value).
 * @param {string} template
 * @param {Record<string, string | number>} values
 */
export function fill(template, values) {
  return template.replace(/\{(\w+)\}/g, (whole, name) => (name in values ? String(values[name]) : whole));
}
