// @ts-check
/**
 * @file The application graph's shape and layout: the hub's `/api/graph` snapshot checked, laid out in columns
 * (producers left, consumers right, by longest path from a source) and turned into boxes and curves. Pure: no DOM,
 * so `node --test` checks it against the vector the hub writes (`crates/contract/vectors/graph.json`).
 */

/** @typedef {{id: number, name: string, label: string, transport: string}} GraphNode */
/**
 * @typedef {{name: string, kind: string, from: number, to: number[], msgs_per_s: number, bytes_per_s: number,
 *   dropped: number}} GraphChannel
 */
/** @typedef {{nodes: GraphNode[], channels: GraphChannel[]}} Graph */
/** @typedef {{id: number, x: number, y: number, w: number, h: number, node: GraphNode}} Box */
/**
 * One curve from a producer to a consumer, carrying every channel between the two (drawn once, labelled with all).
 * @typedef {{channels: GraphChannel[], from: number, to: number, d: string, labelX: number, labelY: number}} Edge
 */

/**
 * Checks a parsed `/api/graph` value; throws naming the first field that does not fit.
 * @param {unknown} value
 * @returns {Graph}
 */
export function parseGraph(value) {
  const v = /** @type {any} */ (value);
  if (!v || !Array.isArray(v.nodes) || !Array.isArray(v.channels)) {
    throw new Error('graph: expected {nodes: [...], channels: [...]}');
  }
  v.nodes.forEach((/** @type {any} */ n, /** @type {number} */ i) => {
    for (const [k, t] of [['id', 'number'], ['name', 'string'], ['label', 'string'], ['transport', 'string']]) {
      if (typeof n[k] !== t) throw new Error(`graph: nodes[${i}].${k} is not a ${t}`);
    }
  });
  v.channels.forEach((/** @type {any} */ c, /** @type {number} */ i) => {
    for (const [k, t] of [['name', 'string'], ['kind', 'string'], ['from', 'number'], ['msgs_per_s', 'number'],
      ['bytes_per_s', 'number'], ['dropped', 'number']]) {
      if (typeof c[k] !== t) throw new Error(`graph: channels[${i}].${k} is not a ${t}`);
    }
    if (!Array.isArray(c.to) || c.to.some((/** @type {unknown} */ t) => typeof t !== 'number')) {
      throw new Error(`graph: channels[${i}].to is not a list of node ids`);
    }
  });
  return /** @type {Graph} */ (v);
}

/**
 * The column of every node: 0 for nodes nothing feeds, else one more than the furthest producer feeding it.
 * Cycles (the brain calls the speech service, whose avatar commands the brain reads) are cut at the edges that
 * lead back into the walk, which starts from the nodes nothing feeds, so sources stay on the left.
 * @param {Graph} graph
 * @returns {Map<number, number>}
 */
export function columns(graph) {
  const ids = graph.nodes.map((n) => n.id).sort((a, b) => a - b);
  /** @type {Map<number, Set<number>>} */
  const out = new Map(ids.map((id) => [id, new Set()]));
  /** @type {Map<number, number>} */
  const fedBy = new Map(ids.map((id) => [id, 0]));
  for (const c of graph.channels) {
    for (const t of c.to) {
      if (t === c.from || !out.has(t) || !out.has(c.from) || out.get(c.from)?.has(t)) continue;
      out.get(c.from)?.add(t);
      fedBy.set(t, (fedBy.get(t) ?? 0) + 1);
    }
  }
  // Depth-first from the sources, then from whatever is left (pure cycles): an edge to a node still on the
  // walk's stack closes a cycle and is left out of the layering.
  /** @type {Set<string>} */
  const back = new Set();
  /** @type {Map<number, 'open' | 'done'>} */
  const seen = new Map();
  /** @param {number} id */
  const walk = (id) => {
    seen.set(id, 'open');
    for (const t of out.get(id) ?? []) {
      const state = seen.get(t);
      if (state === 'open') back.add(`${id}>${t}`);
      else if (state === undefined) walk(t);
    }
    seen.set(id, 'done');
  };
  for (const id of ids) if ((fedBy.get(id) ?? 0) === 0) walk(id);
  for (const id of ids) if (!seen.has(id)) walk(id);
  // Longest path over what is left, in topological order (Kahn).
  /** @type {Map<number, number>} */
  const indegree = new Map(ids.map((id) => [id, 0]));
  for (const [from, tos] of out) {
    for (const t of tos) if (!back.has(`${from}>${t}`)) indegree.set(t, (indegree.get(t) ?? 0) + 1);
  }
  /** @type {Map<number, number>} */
  const column = new Map(ids.map((id) => [id, 0]));
  const ready = ids.filter((id) => indegree.get(id) === 0);
  while (ready.length) {
    const id = /** @type {number} */ (ready.shift());
    for (const t of out.get(id) ?? []) {
      if (back.has(`${id}>${t}`)) continue;
      column.set(t, Math.max(column.get(t) ?? 0, (column.get(id) ?? 0) + 1));
      const left = (indegree.get(t) ?? 0) - 1;
      indegree.set(t, left);
      if (left === 0) ready.push(t);
    }
  }
  return column;
}

/**
 * Boxes for the nodes and curves for the channels (one per subscriber), in a `width` x `height` picture.
 * Within a column, nodes are ordered by the mean row of what feeds them, which keeps most curves short.
 * @param {Graph} graph
 * @param {{width: number, height: number, nodeW?: number, nodeH?: number}} size
 * @returns {{boxes: Box[], edges: Edge[]}}
 */
export function layout(graph, size) {
  const nodeW = size.nodeW ?? 150;
  const nodeH = size.nodeH ?? 40;
  const column = columns(graph);
  const count = Math.max(1, ...[...column.values()].map((c) => c + 1));
  /** @type {number[][]} */
  const byColumn = Array.from({ length: count }, () => []);
  for (const n of graph.nodes) byColumn[column.get(n.id) ?? 0].push(n.id);
  /** @type {Map<number, number>} */
  const row = new Map();
  byColumn.forEach((ids, ci) => {
    const feeders = (/** @type {number} */ id) =>
      graph.channels.filter((c) => c.to.includes(id) && c.from !== id && (column.get(c.from) ?? 0) < ci)
        .map((c) => row.get(c.from) ?? 0);
    const key = (/** @type {number} */ id) => {
      const f = feeders(id);
      return f.length ? f.reduce((a, b) => a + b, 0) / f.length : Number.MAX_SAFE_INTEGER;
    };
    ids.sort((a, b) => key(a) - key(b) || a - b);
    ids.forEach((id, i) => row.set(id, i));
  });
  const colGap = count > 1 ? (size.width - nodeW - 20) / (count - 1) : 0;
  /** @type {Map<number, Box>} */
  const boxes = new Map();
  byColumn.forEach((ids, ci) => {
    const gap = size.height / (ids.length + 1);
    ids.forEach((id, i) => {
      const node = graph.nodes.find((n) => n.id === id);
      if (!node) return;
      boxes.set(id, { id, x: 10 + ci * colGap, y: gap * (i + 1) - nodeH / 2, w: nodeW, h: nodeH, node });
    });
  });
  /** @type {Map<string, Edge>} */
  const edges = new Map();
  for (const c of graph.channels) {
    const a = boxes.get(c.from);
    if (!a) continue;
    c.to.forEach((t) => {
      const b = boxes.get(t);
      if (!b || t === c.from) return;
      const key = `${c.from}>${t}`;
      const known = edges.get(key);
      if (known) {
        known.channels.push(c);
        return;
      }
      // Right side of the producer to the left side of the consumer, as a smooth S.
      const x1 = a.x + a.w;
      const y1 = a.y + a.h / 2;
      const x2 = b.x;
      const y2 = b.y + b.h / 2;
      const bend = Math.max(40, Math.abs(x2 - x1) / 2);
      const d = `M ${x1} ${y1} C ${x1 + bend} ${y1}, ${x2 - bend} ${y2}, ${x2} ${y2}`;
      edges.set(key, { channels: [c], from: c.from, to: t, d, labelX: (x1 + x2) / 2, labelY: (y1 + y2) / 2 });
    });
  }
  return { boxes: [...boxes.values()], edges: [...edges.values()] };
}

/**
 * The label of a curve: its channels' names, the first two and how many more.
 * @param {Edge} e
 * @returns {string}
 */
export function edgeLabel(e) {
  const names = e.channels.map((c) => c.name);
  return names.length > 2 ? `${names.slice(0, 2).join(", ")} +${names.length - 2}` : names.join(", ");
}

/**
 * A channel's rate as people read it: "15.0 msg/s, 812 kB/s".
 * @param {Pick<GraphChannel, "msgs_per_s" | "bytes_per_s">} c the two figures it reads
 * @returns {string}
 */
export function rate(c) {
  const b = c.bytes_per_s;
  const bytes = b >= 1e6 ? `${(b / 1e6).toFixed(1)} MB/s` : b >= 1e3 ? `${(b / 1e3).toFixed(0)} kB/s` : `${b.toFixed(0)} B/s`;
  return `${c.msgs_per_s.toFixed(1)} msg/s, ${bytes}`;
}
