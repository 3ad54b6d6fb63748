// @ts-check
/**
 * @file The `/graph` page: draws the hub's application graph from `/api/graph/stream` (one server-sent event a
 * second) as an SVG picture and a table. `window.graphDebug` shows what was drawn, for the browser test.
 */

import { edgeLabel, layout, parseGraph, rate } from './layout.js';

const SVG = 'http://www.w3.org/2000/svg';
const svg = /** @type {SVGSVGElement} */ (/** @type {unknown} */ (document.getElementById('graph')));
const tbody = /** @type {HTMLTableSectionElement} */ (document.querySelector('#graph-table tbody'));
const pill = /** @type {HTMLElement} */ (document.getElementById('graph-pill'));

/**
 * @type {{updates: number, nodes: string[], edges: {channel: string, from: string, to: string}[], curves: number,
 *   error: string}}
 */
const debug = { updates: 0, nodes: [], edges: [], curves: 0, error: '' };
/** @type {any} */ (window).graphDebug = debug;

/**
 * @param {string} name
 * @param {Record<string, string | number>} attrs
 * @param {string} [text]
 */
function el(name, attrs, text) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  return e;
}

/** @param {import('./layout.js').Graph} graph */
function draw(graph) {
  const width = Math.max(640, svg.clientWidth || 1000);
  const height = Math.max(360, svg.clientHeight || 620);
  svg.setAttribute('viewBox', `0 0 ${width} ${height}`);
  const { boxes, edges } = layout(graph, { width, height });
  const names = new Map(graph.nodes.map((n) => [n.id, n.name]));
  svg.replaceChildren();
  for (const e of edges) {
    const g = el('g', {
      class: 'edge',
      'data-channels': e.channels.map((c) => c.name).join(' '),
      'data-active': String(e.channels.some((c) => c.msgs_per_s > 0)),
      'data-dropping': String(e.channels.some((c) => c.dropped > 0)),
    });
    g.append(el('path', { d: e.d }));
    g.append(el('title', {}, e.channels.map((c) => `${c.name}: ${rate(c)}, ${c.dropped} dropped`).join('\n')));
    g.append(el('text', { x: e.labelX, y: e.labelY - 3, 'text-anchor': 'middle' }, edgeLabel(e)));
    svg.append(g);
  }
  for (const b of boxes) {
    const g = el('g', { class: 'node', 'data-name': b.node.name, 'data-transport': b.node.transport });
    g.append(el('rect', { x: b.x, y: b.y, width: b.w, height: b.h, rx: 8 }));
    g.append(el('text', { x: b.x + 10, y: b.y + 17 }, b.node.name));
    g.append(el('text', { class: 'transport', x: b.x + 10, y: b.y + 31 }, `${b.node.transport} #${b.node.id}`));
    svg.append(g);
  }
  tbody.replaceChildren(
    ...graph.channels.map((c) => {
      const tr = document.createElement('tr');
      const cells = [c.name, c.kind, names.get(c.from) ?? `#${c.from}`,
        c.to.map((t) => names.get(t) ?? `#${t}`).join(', ') || '-', rate(c), String(c.dropped)];
      for (const text of cells) {
        const td = document.createElement('td');
        td.textContent = text;
        tr.append(td);
      }
      return tr;
    }),
  );
  debug.updates += 1;
  debug.nodes = graph.nodes.map((n) => n.name);
  debug.curves = edges.length;
  debug.edges = edges.flatMap((e) => e.channels.map((c) => ({
    channel: c.name, from: names.get(e.from) ?? '', to: names.get(e.to) ?? '',
  })));
}

/** @param {string} text */
function receive(text) {
  try {
    draw(parseGraph(JSON.parse(text)));
    pill.dataset.state = 'open';
    pill.textContent = 'live';
    debug.error = '';
  } catch (e) {
    debug.error = String(e);
    pill.dataset.state = 'closed';
    pill.textContent = 'bad graph';
    console.error(e);
  }
}

const events = new EventSource('/api/graph/stream');
events.addEventListener('graph', (e) => receive(/** @type {MessageEvent} */ (e).data));
// EventSource reconnects by itself; the pill says so meanwhile.
events.onerror = () => {
  pill.dataset.state = 'connecting';
  pill.textContent = 'reconnecting';
};
