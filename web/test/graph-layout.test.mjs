// @ts-check
//! The graph page's layout (web/js/graph/layout.js) on the hub's own graph snapshot (crates/contract/vectors/graph.json,
//! written by a hub test) and on a graph the size of a busy agent.

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { test } from "node:test";

import { columns, edgeLabel, layout, parseGraph, rate } from "../js/graph/layout.js";

const vector = JSON.parse(readFileSync(new URL("../../crates/contract/vectors/graph.json", import.meta.url), "utf8"));

test("the hub's graph snapshot parses and producers sit left of their consumers", () => {
  const g = parseGraph(vector);
  const col = columns(g);
  for (const c of g.channels) {
    for (const t of c.to) assert.ok(col.get(c.from) < col.get(t), `${c.name}: ${c.from} -> ${t}`);
  }
  const { boxes, edges } = layout(g, { width: 900, height: 500 });
  assert.equal(boxes.length, g.nodes.length);
  assert.equal(edges.reduce((n, e) => n + e.channels.length, 0), g.channels.reduce((n, c) => n + c.to.length, 0));
  for (const e of edges) assert.match(e.d, /^M [\d.]+ [\d.]+ C /);
});

test("a graph that does not fit the shape is refused naming the field", () => {
  assert.throws(() => parseGraph({ nodes: [{ id: "x" }], channels: [] }), /nodes\[0\]\.id/);
  assert.throws(() => parseGraph({ nodes: [], channels: [{ name: "a", kind: "stream", from: 1, to: "b",
    msgs_per_s: 0, bytes_per_s: 0, dropped: 0 }] }), /channels\[0\]\.to/);
  assert.throws(() => parseGraph(null), /nodes/);
});

test("twenty nodes in a chain with a cycle are laid out without overlaps inside the picture", () => {
  const nodes = Array.from({ length: 20 }, (_, i) => ({ id: i + 1, name: `n${i + 1}`, label: `n#${i + 1}`,
    transport: i % 2 ? "tcp" : "module" }));
  const channels = nodes.slice(1).map((n, i) => ({ name: `C${i}`, kind: "stream", from: (i % 5) + 1,
    to: [n.id], msgs_per_s: 15, bytes_per_s: 800000, dropped: 0 }));
  channels.push({ name: "Back", kind: "stream", from: 20, to: [1], msgs_per_s: 1, bytes_per_s: 10, dropped: 2 });
  const { boxes } = layout(parseGraph({ nodes, channels }), { width: 1200, height: 620 });
  assert.equal(boxes.length, 20);
  for (const a of boxes) {
    assert.ok(a.x >= 0 && a.x + a.w <= 1200 && a.y >= 0 && a.y + a.h <= 620, `node ${a.id} outside`);
    for (const b of boxes) {
      if (a === b) continue;
      const apart = a.x + a.w <= b.x || b.x + b.w <= a.x || a.y + a.h <= b.y || b.y + b.h <= a.y;
      assert.ok(apart, `nodes ${a.id} and ${b.id} overlap`);
    }
  }
});

test("rates read as messages and bytes per second", () => {
  assert.equal(rate({ msgs_per_s: 15, bytes_per_s: 812000 }), "15.0 msg/s, 812 kB/s");
  assert.equal(rate({ msgs_per_s: 0.5, bytes_per_s: 2_500_000 }), "0.5 msg/s, 2.5 MB/s");
});

test("a cycle leaves the source on the left", () => {
  const node = (id) => ({ id, name: `n${id}`, label: `n#${id}`, transport: "module" });
  const edge = (name, from, to) => ({ name, kind: "stream", from, to: [to], msgs_per_s: 1, bytes_per_s: 1,
    dropped: 0 });
  // 1 (camera) -> 2 (vision) -> 3 (brain) -> 4 (tts) -> 3 (avatar back to the brain)
  const g = parseGraph({ nodes: [node(1), node(2), node(3), node(4)],
    channels: [edge("video", 1, 2), edge("detections", 2, 3), edge("say", 3, 4), edge("avatar", 4, 3)] });
  const col = columns(g);
  assert.deepEqual([1, 2, 3, 4].map((id) => col.get(id)), [0, 1, 2, 3]);
});

test("channels between the same two nodes share one curve and its label", () => {
  const node = (id) => ({ id, name: `n${id}`, label: `n#${id}`, transport: "module" });
  const edge = (name) => ({ name, kind: "stream", from: 1, to: [2], msgs_per_s: 1, bytes_per_s: 1, dropped: 0 });
  const g = parseGraph({ nodes: [node(1), node(2)], channels: ["A", "B", "C"].map(edge) });
  const { edges } = layout(g, { width: 800, height: 400 });
  assert.equal(edges.length, 1);
  assert.deepEqual(edges[0].channels.map((c) => c.name), ["A", "B", "C"]);
  assert.equal(edgeLabel(edges[0]), "A, B +1");
});
