//! The rule-trace panel: the brain's rule changes from `Agent.rules`, newest first.

const MAX_ENTRIES = 50;

export class RuleTrace {
  constructor(list, meta) {
    this.list = list;
    this.meta = meta;
    this.count = 0;
  }

  add(data) {
    if (!data || typeof data !== "object") return;
    this.count += 1;
    const li = document.createElement("li");
    const time = document.createElement("span");
    time.className = "r-time";
    const ts = Number.isFinite(data.ts_ms) ? new Date(data.ts_ms) : new Date();
    time.textContent = ts.toLocaleTimeString([], { hour12: false });
    li.append(time);
    const rule = document.createElement("b");
    rule.textContent = String(data.rule ?? "?");
    li.append(rule);
    if (data.action) li.append(` → ${String(data.action)}`);
    // A barge-in entry: the reply the user cut off by speaking over it.
    if (typeof data.interrupted === "string") li.classList.add("r-interrupted");
    if (Array.isArray(data.because) && data.because.length > 0) {
      const because = document.createElement("span");
      because.className = "r-because";
      because.textContent = `because ${data.because.map(String).join(", ")}`;
      li.append(because);
    }
    this.list.prepend(li);
    while (this.list.children.length > MAX_ENTRIES) this.list.lastElementChild.remove();
    this.meta.textContent = data.program ? String(data.program) : `${this.count} changes`;
  }
}
