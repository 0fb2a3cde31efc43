// ndds studio: the page. It talks only to the studio process (one WebSocket, JSON messages;
// ndds-studio/src/web.rs documents them) and draws with Cytoscape.js and uPlot.
'use strict';

// Errors of the page itself, kept for the tests (and shown in the banner).
window.studioErrors = [];
window.addEventListener('error', (event) => {
  window.studioErrors.push(String(event.message));
  const banner = document.getElementById('banner');
  banner.hidden = false;
  banner.textContent = `page error: ${event.message}`;
});

const $ = (id) => document.getElementById(id);
const el = (tag, attrs = {}, ...children) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
};

const state = {
  writable: false,
  network: null,
  systems: {},      // runtime -> SystemDescription
  stats: {},        // runtime/habitat -> HabitatStats
  machines: {},     // machine -> MachineState
  replies: {},      // id -> callback
  nextId: 1,
  values: {},       // runtime -> {mat: {rows, cols, data}}
  fields: {},       // topic -> field names
  gone: {},         // element id -> time it disappeared
};

// ---- connection -------------------------------------------------------------------------
const token = new URLSearchParams(location.hash.slice(1)).get('token') || '';
let ws;
function connect() {
  ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => {
    $('conn').textContent = 'connected';
    $('conn').classList.remove('bad');
    if (token) send({ type: 'auth', token });
    for (const topic of watchedTopics()) send({ type: 'watch', topic });
  };
  ws.onclose = () => {
    $('conn').textContent = 'disconnected: retrying';
    $('conn').classList.add('bad');
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => handle(JSON.parse(event.data));
}
function send(message) {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(message));
}
function command(body, reply) {
  const id = state.nextId++;
  state.replies[id] = reply;
  send({ type: 'command', id, command: body });
}
function showReply(target, ok, text) {
  const node = $(target);
  node.textContent = text;
  node.className = 'reply ' + (ok ? 'ok' : 'bad');
}

function handle(m) {
  switch (m.type) {
    case 'hello':
      state.writable = m.writable;
      $('access').textContent = m.writable ? 'may change the system' : 'view only (no token)';
      break;
    // A view is drawn while it is shown, and when it is shown again (a hidden view costs the
    // page nothing).
    case 'network':
      state.network = m.network;
      if (shown('network')) renderNetwork();
      fillPlotTopics();
      break;
    case 'system':
      state.systems[m.system.runtime] = m.system;
      fillSelect($('sys-select'), Object.keys(state.systems));
      fillSelect($('fsm-select'), machineNames());
      if (shown('system')) renderSystem();
      if (shown('fsm')) renderMachine();
      break;
    case 'stats':
      state.stats[`${m.stats.runtime}/${m.stats.habitat}`] = m.stats;
      if (shown('system')) renderHabitats();
      break;
    case 'machine':
      state.machines[m.state.machine] = m.state;
      fillSelect($('fsm-select'), machineNames());
      if (shown('fsm')) renderMachine();
      break;
    case 'points':
      addPoints(m.topic, m.data);
      break;
    case 'reply': {
      const callback = state.replies[m.id];
      delete state.replies[m.id];
      if (callback) callback(m.ok, m.text);
      break;
    }
    case 'editor':
      editorMessage(m);
      break;
    case 'error':
      if (m.topic) showReply('plot-reply', false, m.text);
      else { $('banner').hidden = false; $('banner').textContent = m.text; }
      break;
  }
}

function shown(view) {
  return $(`view-${view}`).classList.contains('active');
}

function fillSelect(select, names) {
  const current = select.value;
  const have = [...select.options].map((o) => o.value).join('\n');
  if (have === names.join('\n')) return;
  select.replaceChildren(...names.map((n) => el('option', { value: n }, n)));
  if (names.includes(current)) select.value = current;
}

// ---- views ------------------------------------------------------------------------------
for (const button of document.querySelectorAll('nav button')) {
  button.addEventListener('click', () => {
    for (const b of document.querySelectorAll('nav button')) b.classList.toggle('active', b === button);
    for (const v of document.querySelectorAll('.view')) v.classList.toggle('active', v.id === `view-${button.dataset.view}`);
    ({ network: renderNetwork, system: renderSystem, fsm: renderMachine }[button.dataset.view] || (() => {}))();
    // A graph laid out while its view was hidden has no size: fit it now it shows.
    const shownGraphs = { network: [graphs.net], system: [graphs.sys], fsm: [graphs.fsm], editor: [graphs.ed, graphs.edFsm] }[button.dataset.view] || [];
    // Its elements are added again: sizes measured while hidden (labels of no width) are
    // kept by Cytoscape's style caches, and such nodes would not be drawn.
    for (const shown of shownGraphs) {
      shown.resize();
      const elements = shown.elements().jsons();
      shown.elements().remove();
      shown.add(elements);
      shown.fit(undefined, 30);
    }
    for (const p of plots) if (p.plot) p.plot.setSize(plotSize());
    if (button.dataset.view === 'editor') editorShown();
  });
}

const graphStyle = [
  // Fixed sizes: sizes from labels measured at the wrong moment were cached as 0 by
  // Cytoscape, which then drew neither those nodes nor their edges.
  { selector: 'node', style: { label: 'data(label)', 'font-size': 10, 'text-valign': 'center', 'text-wrap': 'wrap', 'text-max-width': 124, width: 130, height: 34, shape: 'round-rectangle', 'background-color': '#e3ecf4', 'border-width': 1, 'border-color': '#7d93a8' } },
  { selector: 'node:parent', style: { 'text-valign': 'top', 'background-opacity': 0.25, 'font-weight': 'bold' } },
  { selector: 'node.topic', style: { shape: 'ellipse', 'background-color': '#fff7df', 'border-color': '#c7a43c' } },
  { selector: 'node.port', style: { shape: 'diamond', 'background-color': '#efe5fb', 'border-color': '#8c6bb8' } },
  { selector: 'node.host', style: { 'background-color': '#dfe7ee' } },
  { selector: 'node[colour]', style: { 'background-color': 'data(colour)', color: '#fff', 'border-color': '#333' } },
  { selector: 'node.habitat', style: { 'background-opacity': 0, 'border-width': 0, 'font-weight': 'bold', 'font-size': 12, width: 90 } },
  { selector: 'node.inactive', style: { opacity: 0.35 } },
  { selector: 'node.current', style: { 'background-color': '#2b7bbf', color: '#fff', 'border-color': '#174b78', 'border-width': 3 } },
  { selector: 'node.star', style: { shape: 'star', width: 30, height: 30, label: '*' } },
  { selector: '.fading', style: { opacity: 0.3 } },
  { selector: 'edge', style: { width: 1.5, 'curve-style': 'bezier', 'target-arrow-shape': 'triangle', 'line-color': '#8aa0b4', 'target-arrow-color': '#8aa0b4', label: 'data(label)', 'font-size': 9, 'text-rotation': 'autorotate', 'text-background-color': '#fff', 'text-background-opacity': 0.8 } },
  { selector: 'edge.mismatch', style: { 'line-color': '#d2402f', 'target-arrow-color': '#d2402f', 'line-style': 'dashed', width: 2.5 } },
  { selector: 'edge.fired', style: { 'line-color': '#2b7bbf', 'target-arrow-color': '#2b7bbf', width: 3 } },
  { selector: 'node.problem', style: { 'border-color': '#d2402f', 'border-width': 3, 'border-style': 'dashed' } },
  { selector: 'node.source', style: { shape: 'round-tag', 'background-color': '#fff7df', 'border-color': '#c7a43c', width: 110 } },
  { selector: ':selected', style: { 'border-color': '#f08c00', 'border-width': 3, 'line-color': '#f08c00' } },
];
const graphs = {
  net: cytoscape({ container: $('net-graph'), style: graphStyle, wheelSensitivity: 0.3 }),
  sys: cytoscape({ container: $('sys-graph'), style: graphStyle, wheelSensitivity: 0.3 }),
  fsm: cytoscape({ container: $('fsm-graph'), style: graphStyle, wheelSensitivity: 0.3 }),
};

// Replaces a graph's elements when what it draws changed (by a key), keeping positions.
function setElements(cy, elements, key, layout) {
  if (cy.scratch('key') === key) return false;
  cy.scratch('key', key);
  cy.elements().remove();
  cy.add(elements);
  cy.layout(layout).run();
  cy.fit(undefined, 30);
  return true;
}

// ---- network ----------------------------------------------------------------------------
function netFilters() {
  return {
    host: $('net-host').value,
    prefix: $('net-prefix').value.trim(),
    processes: $('net-processes').checked,
    ports: $('net-ports').checked,
    internal: $('net-internal').checked,
  };
}
for (const id of ['net-host', 'net-prefix', 'net-processes', 'net-ports', 'net-internal']) {
  $(id).addEventListener('input', renderNetwork);
}

function renderNetwork() {
  const net = state.network;
  if (!net) return;
  const f = netFilters();
  fillSelect($('net-host'), ['', ...net.hosts.map((h) => h.id)]);
  for (const o of $('net-host').options) {
    const h = net.hosts.find((x) => x.id === o.value);
    o.textContent = h ? `${h.hostname}${h.local ? ' (this host)' : ''}` : 'all';
  }
  const processOf = Object.fromEntries(net.processes.map((p) => [p.id, p]));
  const hostOf = Object.fromEntries(net.hosts.map((h) => [h.id, h]));
  const topicShown = (t) => (f.internal || !t.internal) && (!f.prefix || t.name.startsWith(f.prefix));
  const endpointShown = (e) => !f.host || (processOf[e.process] && processOf[e.process].host === f.host);
  const topics = net.topics.filter(topicShown);
  const shownTopics = new Set(topics.map((t) => t.name));
  const endpoints = net.endpoints.filter((e) => shownTopics.has(e.topic) && endpointShown(e));
  const mismatchOf = new Set(net.mismatches.map((m) => `${m.topic}|${m.producer}`).concat(net.mismatches.map((m) => `${m.topic}|${m.consumer}`)));
  const elements = [];
  const usedHosts = new Set();
  const usedProcesses = new Set();
  for (const e of endpoints) usedProcesses.add(e.process);
  if (f.ports) for (const p of net.ports) for (const x of p.owners.concat(p.users)) usedProcesses.add(x);
  for (const pid of usedProcesses) {
    const p = processOf[pid];
    if (!p || (f.host && p.host !== f.host)) continue;
    usedHosts.add(p.host);
  }
  for (const hid of usedHosts) {
    const h = hostOf[hid];
    const remaining = h && h.expires_in_ms != null && h.lease_ms ? h.expires_in_ms / h.lease_ms : 1;
    elements.push({ group: 'nodes', data: { id: `host:${hid}`, label: h ? h.hostname : hid, kind: 'host' }, classes: 'host' + (remaining < 0.5 ? ' fading' : '') });
  }
  if (f.processes) {
    for (const pid of usedProcesses) {
      const p = processOf[pid];
      if (!p || !usedHosts.has(p.host)) continue;
      elements.push({ group: 'nodes', data: { id: `proc:${pid}`, parent: `host:${p.host}`, label: `${p.name} (${p.pid})`, kind: 'process' } });
    }
  }
  for (const t of topics) {
    if (t.name.startsWith('port/')) continue;
    const rate = t.rate_hz != null ? `\n${t.rate_hz.toFixed(1)} Hz` : '';
    elements.push({ group: 'nodes', data: { id: `topic:${t.name}`, label: t.name + rate, kind: 'topic', name: t.name }, classes: 'topic' });
  }
  if (f.ports) {
    for (const p of net.ports) {
      elements.push({ group: 'nodes', data: { id: `port:${p.name}`, label: p.name, kind: 'port', name: p.name }, classes: 'port' });
      for (const [list, role] of [[p.owners, 'owns'], [p.users, 'uses']]) {
        for (const x of list) {
          if (!f.processes || !processOf[x] || !usedHosts.has(processOf[x].host)) continue;
          elements.push({ group: 'edges', data: { id: `${role}:${x}:${p.name}`, source: `proc:${x}`, target: `port:${p.name}`, label: role } });
        }
      }
    }
  }
  if (f.processes) {
    const seen = new Set();
    for (const e of endpoints) {
      if (e.topic.startsWith('port/') || !processOf[e.process]) continue;
      const [source, target] = e.kind === 'producer' ? [`proc:${e.process}`, `topic:${e.topic}`] : [`topic:${e.topic}`, `proc:${e.process}`];
      const id = `${source}>${target}`;
      if (seen.has(id)) continue;
      seen.add(id);
      const bad = mismatchOf.has(`${e.topic}|${e.guid}`);
      const fading = e.expires_in_ms != null && e.expires_in_ms < 2000;
      elements.push({ group: 'edges', data: { id, source, target, label: '', topic: e.topic, kind: e.kind }, classes: (bad ? 'mismatch' : '') + (fading ? ' fading' : '') });
    }
  }
  const key = JSON.stringify(elements.map((x) => [x.data.id, x.classes]).sort());
  const structural = JSON.stringify(elements.map((x) => x.data.id).sort());
  const cy = graphs.net;
  if (cy.scratch('structure') !== structural) {
    cy.scratch('structure', structural);
    setElements(cy, elements, key, { name: 'cose', animate: false, padding: 20, nodeRepulsion: () => 9000, idealEdgeLength: () => 90 });
  } else {
    for (const x of elements) {
      const e = cy.getElementById(x.data.id);
      e.data('label', x.data.label);
      e.classes(x.classes || '');
    }
  }
  renderTopicTable(net, topics);
}

function renderTopicTable(net, topics) {
  const body = $('net-topics').tBodies[0];
  const rows = topics.map((t) => {
    const bad = net.mismatches.filter((m) => m.topic === t.name);
    const tr = el('tr', { class: bad.length ? 'mismatch' : '', 'data-topic': t.name },
      el('td', { class: 'mono' }, t.name),
      el('td', { class: 'mono' }, t.types.join(', ')),
      el('td', { class: 'num' }, t.producers),
      el('td', { class: 'num' }, t.consumers),
      el('td', { class: 'num' }, t.rate_hz != null ? `${t.rate_hz.toFixed(1)} Hz` : ''),
      el('td', { class: 'num' }, t.lost != null ? t.lost : ''),
      el('td', {}, bad.length ? `${bad.length} pair(s) do not match: ${bad[0].reason}` : (t.producers && t.consumers ? 'matched' : '')));
    tr.addEventListener('click', () => showTopic(t.name));
    return tr;
  });
  body.replaceChildren(...rows);
}

function showTopic(name) {
  const net = state.network;
  const t = net.topics.find((x) => x.name === name);
  if (!t) return;
  const processOf = Object.fromEntries(net.processes.map((p) => [p.id, p]));
  const box = $('net-details');
  const list = (kind) => net.endpoints.filter((e) => e.topic === name && e.kind === kind).map((e) =>
    el('li', {}, `${processOf[e.process] ? processOf[e.process].name : e.process} — ${e.type_name} `, el('code', {}, e.fingerprint), ` — ${e.qos}`));
  const bad = net.mismatches.filter((m) => m.topic === name);
  box.replaceChildren(
    el('h3', {}, name),
    el('p', {}, t.rate_hz != null ? `${t.rate_hz.toFixed(1)} samples/s, ${t.lost} lost` : 'rate not measured'),
    el('b', {}, 'Producers'), el('ul', {}, ...list('producer')),
    el('b', {}, 'Consumers'), el('ul', {}, ...list('consumer')),
    ...(bad.length ? [el('b', {}, 'Why not matched'), el('ul', { id: 'why-not' }, ...bad.map((m) => el('li', {}, m.reason)))] : []));
}

graphs.net.on('tap', 'node', (event) => {
  const d = event.target.data();
  if (d.kind === 'topic') showTopic(d.name);
  else if (d.kind === 'port') {
    const p = state.network.ports.find((x) => x.name === d.name);
    $('net-details').replaceChildren(el('h3', {}, `port ${d.name}`), el('p', {}, `owners: ${p.owners.join(', ') || 'none'}`), el('p', {}, `users: ${p.users.join(', ') || 'none'}`));
  } else $('net-details').replaceChildren(el('h3', {}, d.label));
});
graphs.net.on('tap', 'edge', (event) => showTopic(event.target.data('topic')));

// ---- systems ----------------------------------------------------------------------------
const palette = ['#4e79a7', '#f28e2b', '#59a14f', '#e15759', '#76b7b2', '#edc948', '#b07aa1', '#ff9da7', '#9c755f', '#bab0ac'];
function groupColour(system, group) {
  const i = system.groups.findIndex((g) => `${g.category}/${g.name}` === group);
  return palette[(i < 0 ? 0 : i) % palette.length];
}
$('sys-select').addEventListener('input', renderSystem);

function selectedSystem() {
  return state.systems[$('sys-select').value];
}

function renderSystem() {
  const s = selectedSystem();
  if (!s) return;
  $('sys-config').textContent = s.configuration || 'none';
  $('sys-configs').replaceChildren(...s.configurations.map((c) => el('button', {
    class: 'config' + (c.name === s.configuration ? ' active' : ''),
    'data-configuration': c.name,
    title: c.groups.map(([cat, g]) => `${cat}/${g}`).join(', '),
    onclick: () => command({ command: 'configure', runtime: s.runtime, configuration: c.name }, (ok, text) => showReply('sys-reply', ok, text)),
  }, c.name)));
  // Data flow: habitats as rows, modules in execution order; inactive modules after them.
  const elements = [];
  const writers = {};
  for (const m of s.modules) for (const o of m.outputs) (writers[o.mat] = writers[o.mat] || []).push(m.name);
  const position = {};
  s.habitats.forEach((h, row) => {
    // A habitat is a row headed by its name and rate (compound parents hid the modules that
    // have outgoing edges in Cytoscape 3.35 with preset positions).
    elements.push({ group: 'nodes', data: { id: `hab:${h.name}`, label: `${h.name}\n${h.rate_hz.toFixed(0)} Hz${h.running ? '' : ' (stopped)'}` }, position: { x: -190, y: 130 * row }, classes: 'habitat' });
    const members = s.modules.filter((m) => m.habitat === h.name);
    const ordered = h.order.concat(members.map((m) => m.name).filter((n) => !h.order.includes(n)));
    ordered.forEach((name, col) => { position[name] = { x: 170 * col, y: 130 * row }; });
  });
  for (const m of s.modules) {
    const group = m.groups[0];
    const label = `${m.name}${m.component ? `\n${m.component}` : ''}`;
    const data = { id: `mod:${m.name}`, label, module: m.name, habitat: m.habitat };
    if (group) data.colour = groupColour(s, group);
    elements.push({ group: 'nodes', data, position: position[m.name] || { x: 0, y: 0 }, classes: m.active ? '' : 'inactive' });
  }
  const seen = new Set();
  for (const m of s.modules) {
    for (const i of m.inputs) {
      for (const w of writers[i.mat] || []) {
        const id = `${w}>${m.name}:${i.mat}`;
        if (seen.has(id)) continue;
        seen.add(id);
        elements.push({ group: 'edges', data: { id, source: `mod:${w}`, target: `mod:${m.name}`, label: i.mat } });
      }
    }
  }
  setElements(graphs.sys, elements, JSON.stringify(s), { name: 'preset', padding: 30 });
  $('sys-legend').replaceChildren(...s.groups.map((g) => el('span', {},
    el('span', { class: 'swatch', style: `background:${groupColour(s, `${g.category}/${g.name}`)}` }),
    `${g.category}/${g.name}${g.active ? ' (active)' : ''}`)));
  renderHabitats();
  renderParams(s);
}

function renderHabitats() {
  const s = selectedSystem();
  if (!s) return;
  $('sys-habitats').tBodies[0].replaceChildren(...s.habitats.map((h) => {
    const st = state.stats[`${s.runtime}/${h.name}`];
    return el('tr', {},
      el('td', {}, h.name), el('td', { class: 'num' }, `${h.rate_hz.toFixed(1)} Hz`), el('td', {}, h.running ? 'yes' : 'no'),
      el('td', { class: 'num' }, st ? st.samples : ''), el('td', { class: 'num' }, st ? st.overruns : ''),
      el('td', { class: 'num' }, st ? `${st.period_jitter.p99_us.toFixed(0)} µs` : ''),
      el('td', { class: 'mono' }, h.order.join(' → ')));
  }));
}

// Parameters and reference inputs: CSMats some module reads and none writes.
function parameters(s) {
  const written = new Set(s.modules.flatMap((m) => m.outputs.map((o) => o.mat)));
  const readers = {};
  for (const m of s.modules) for (const i of m.inputs) if (!written.has(i.mat)) (readers[i.mat] = readers[i.mat] || []).push(m.name);
  return s.mats.filter((mat) => readers[mat.name]).map((mat) => ({ mat, readers: readers[mat.name] }));
}

function formatValue(v) {
  if (!v) return '';
  if (v.error) return v.error;
  return v.data.map((x) => Number(x.toPrecision(6))).join(', ');
}

function renderParams(s) {
  const body = $('sys-params').tBodies[0];
  const values = state.values[s.runtime] || {};
  const existing = new Map([...body.rows].map((r) => [r.dataset.mat, r]));
  const rows = parameters(s).map(({ mat, readers }) => {
    let tr = existing.get(mat.name);
    if (!tr) {
      const input = el('input', { size: 18, 'data-mat': mat.name });
      const button = el('button', { onclick: () => {
        const numbers = input.value.split(/[\s,]+/).filter((x) => x !== '').map(Number);
        command({ command: 'set', runtime: s.runtime, mat: mat.name, values: numbers }, (ok, text) => { showReply('sys-reply', ok, text); readValues(); });
      } }, 'Set');
      input.addEventListener('keydown', (e) => { if (e.key === 'Enter') button.click(); });
      tr = el('tr', { 'data-mat': mat.name }, el('td', { class: 'mono' }, mat.name), el('td', {}, `${mat.rows}×${mat.cols}`),
        el('td', {}, readers.join(', ')), el('td', { class: 'mono value' }, ''), el('td', {}, input), el('td', {}, button));
    }
    tr.querySelector('.value').textContent = formatValue(values[mat.name]);
    return tr;
  });
  body.replaceChildren(...rows);
}

// Live values: the parameters' and the module in focus's CSMats, twice a second while the
// systems view is shown.
let focusModule = null;
function readValues() {
  const s = selectedSystem();
  if (!s || !$('view-system').classList.contains('active')) return;
  const names = new Set(parameters(s).map((p) => p.mat.name));
  const m = s.modules.find((x) => x.name === focusModule);
  if (m) for (const p of m.inputs.concat(m.outputs)) names.add(p.mat);
  if (!names.size) return;
  command({ command: 'read', runtime: s.runtime, mats: [...names] }, (ok, text) => {
    if (!ok) return;
    state.values[s.runtime] = JSON.parse(text);
    renderParams(s);
    showModule();
  });
}
setInterval(readValues, 500);

function showModule() {
  const s = selectedSystem();
  const m = s && s.modules.find((x) => x.name === focusModule);
  if (!m) return;
  const values = state.values[s.runtime] || {};
  const row = (p) => el('tr', {}, el('td', {}, p.role), el('td', { class: 'mono' }, p.mat), el('td', {}, p.usage), el('td', { class: 'mono' }, formatValue(values[p.mat])));
  $('sys-details').replaceChildren(
    el('h3', {}, m.name),
    el('p', {}, `${m.component || 'runtime module'} in ${m.habitat}${m.groups.length ? `, group ${m.groups.join(', ')}` : ''}${m.active ? '' : ' (inactive)'}`),
    el('table', {}, el('tbody', {}, ...m.inputs.map(row), ...m.outputs.map(row))));
}
for (const ev of ['mouseover', 'tap']) {
  graphs.sys.on(ev, 'node', (event) => {
    const name = event.target.data('module');
    if (!name) return;
    focusModule = name;
    showModule();
    readValues();
  });
}

// ---- state machines ---------------------------------------------------------------------
function machineNames() {
  const names = new Set(Object.keys(state.machines));
  for (const s of Object.values(state.systems)) for (const m of s.machines) names.add(m.name);
  return [...names].sort();
}
function machineProgram(name) {
  for (const s of Object.values(state.systems)) for (const m of s.machines) if (m.name === name) return m;
  return null;
}
$('fsm-select').addEventListener('input', renderMachine);

function renderMachine() {
  const name = $('fsm-select').value;
  const program = machineProgram(name);
  const st = state.machines[name];
  $('fsm-state').textContent = st ? st.state : '?';
  if (program) {
    const elements = [];
    const sub = program.graphs.length > 1;
    for (const g of program.graphs) {
      if (sub) elements.push({ group: 'nodes', data: { id: `m:${g.name}`, label: g.name } });
      for (const s of g.states) elements.push({ group: 'nodes', data: { id: `s:${g.name}:${s}`, parent: sub ? `m:${g.name}` : undefined, label: s + (g.returns.some(([r]) => r === s) ? ' (return)' : '') } });
      let star = false;
      g.transitions.forEach((t, i) => {
        if (t.from == null && !star) { star = true; elements.push({ group: 'nodes', data: { id: `star:${g.name}`, parent: sub ? `m:${g.name}` : undefined, label: '*' }, classes: 'star' }); }
        const source = t.from == null ? `star:${g.name}` : `s:${g.name}:${t.from}`;
        for (const [code, next] of t.next) {
          const action = t.action === 'none' ? '' : ` / ${t.action}`;
          const codeText = t.next.length > 1 ? ` [${code}]` : '';
          elements.push({ group: 'edges', data: { id: `t:${g.name}:${i}:${code}`, source, target: `s:${g.name}:${next}`, label: `${t.when}${action}${codeText}`, when: t.when, from: t.from, to: next, machine: g.name } });
        }
      });
    }
    setElements(graphs.fsm, elements, JSON.stringify(program), { name: 'breadthfirst', directed: true, padding: 30, spacingFactor: 1.4 });
  }
  // The current state (and the call stack's), and the last transition.
  graphs.fsm.nodes().removeClass('current');
  graphs.fsm.edges().removeClass('fired');
  if (st) {
    const stack = st.stack.length ? st.stack : [`${name}:${st.state}`];
    for (const entry of stack) graphs.fsm.getElementById(`s:${entry}`).addClass('current');
    graphs.fsm.getElementById(`s:${name}:${st.state}`).addClass('current');
    const last = st.last_transition;
    if (last) {
      graphs.fsm.edges().filter((e) => e.data('machine') === last.machine && e.data('to') === last.to && e.data('when') === last.condition && (e.data('from') == null || e.data('from') === last.from)).addClass('fired');
    }
  }
  renderMachineDetails(name, program, st);
}

function renderMachineDetails(name, program, st) {
  const box = $('fsm-details');
  const parts = [el('h3', {}, name)];
  if (st) {
    const last = st.last_transition;
    parts.push(el('p', { id: 'fsm-last' }, last ? `last: ${last.from} → ${last.to} on ${last.condition}${last.action && last.action !== 'none' ? ` / ${last.action}` : ''}${last.code != null ? ` (code ${last.code})` : ''}` : 'no transition yet'));
    parts.push(el('p', {}, `latched: ${st.latched.join(', ') || 'none'}`));
    if (st.conditions.length) parts.push(el('p', {}, `conditions: ${st.conditions.map(([k, v]) => `${k} = ${v}`).join(', ')}`));
    parts.push(el('p', {}, `${st.transitions} transitions, ${st.faults} faults${st.last_fault ? ` (last: ${st.last_fault})` : ''}`));
  }
  if (program) {
    const buttons = el('div', { class: 'stimulus' });
    for (const [stimulus, kind] of program.stimuli) {
      if (kind === 'condition') {
        const input = el('input', { size: 8, placeholder: 'value', 'data-stimulus': stimulus });
        buttons.append(el('span', {}, `${stimulus} = `, input, el('button', { onclick: () => sendStimulus(name, `${stimulus}=${input.value}`) }, 'set'), ' '));
      } else {
        buttons.append(el('button', { 'data-stimulus': stimulus, title: kind, onclick: () => sendStimulus(name, stimulus) }, `${stimulus} (${kind})`));
      }
    }
    const free = el('input', { size: 22, placeholder: 'Name or Name=value, ...', id: 'fsm-free' });
    parts.push(el('b', {}, 'Send a stimulus'), buttons, el('div', {}, free, el('button', { onclick: () => sendStimulus(name, free.value) }, 'send')));
  }
  box.replaceChildren(...parts);
}

function sendStimulus(machine, stimuli) {
  command({ command: 'stimulus', machine, stimuli }, (ok, text) => showReply('fsm-reply', ok, text));
}

// ---- plots ------------------------------------------------------------------------------
const plots = [];   // {series: [{topic, field}], rows: Map(t -> values[]), plot, element, points}
let paused = false;
function plotSize() { return { width: Math.max(400, $('plots').clientWidth - 20), height: 240 }; }
function watchedTopics() { return new Set(plots.flatMap((p) => p.series.map((s) => s.topic))); }

function fillPlotTopics() {
  const names = state.network.topics.filter((t) => !t.name.startsWith('port/') && !t.name.endsWith('/description') && t.producers > 0).map((t) => t.name);
  fillSelect($('plot-topic'), names);
  fillPlotFields();
}
function fillPlotFields() {
  const topic = $('plot-topic').value;
  const fields = state.fields[topic];
  if (topic && !fields) { send({ type: 'watch', topic }); state.fields[topic] = []; }
  fillSelect($('plot-field'), state.fields[topic] || []);
}
$('plot-topic').addEventListener('input', fillPlotFields);

function newPlot() {
  const element = el('div', { class: 'plot', 'data-points': '0' });
  const title = el('div', { class: 'title' }, 'empty plot: choose a topic and a field, then "Add to plot"');
  element.append(title);
  $('plots').append(element);
  const p = { series: [], rows: new Map(), plot: null, element, title, points: 0 };
  plots.push(p);
  return p;
}
function makePlot(p) {
  if (p.plot) p.plot.destroy();
  const opts = {
    ...plotSize(),
    scales: { x: { time: true } },
    series: [{}, ...p.series.map((s, i) => ({ label: `${s.topic} ${s.field}`, stroke: palette[i % palette.length], spanGaps: true }))],
    cursor: { drag: { x: true, y: false } },
  };
  p.plot = new uPlot(opts, [[], ...p.series.map(() => [])], p.element);
  p.title.replaceChildren(`${p.series.length} series`, el('button', { onclick: () => { p.series = []; p.rows.clear(); makePlot(p); } }, 'clear'));
}
$('plot-new').addEventListener('click', () => newPlot());
$('plot-add').addEventListener('click', () => {
  const topic = $('plot-topic').value;
  const field = $('plot-field').value;
  if (!topic || !field) { showReply('plot-reply', false, 'choose a topic and one of its fields (fields appear with its first samples)'); return; }
  const p = plots.length ? plots[plots.length - 1] : newPlot();
  if (p.series.some((s) => s.topic === topic && s.field === field)) return;
  p.series.push({ topic, field });
  send({ type: 'watch', topic });
  makePlot(p);
  showReply('plot-reply', true, `plotting ${topic} ${field}`);
});
$('plot-pause').addEventListener('click', () => {
  paused = !paused;
  $('plot-pause').textContent = paused ? 'Resume' : 'Pause';
});

function addPoints(topic, data) {
  if (data.error) showReply('plot-reply', false, `${topic}: ${data.error}`);
  const fresh = !state.fields[topic] || state.fields[topic].join('\n') !== data.fields.join('\n');
  state.fields[topic] = data.fields;
  if (fresh && $('plot-topic').value === topic) fillPlotFields();
  if (paused) return;
  for (const p of plots) {
    p.series.forEach((s, i) => {
      if (s.topic !== topic) return;
      const f = data.fields.indexOf(s.field);
      if (f < 0) return;
      for (const [t, v] of data.points[f]) {
        let row = p.rows.get(t);
        if (!row) { row = new Array(p.series.length).fill(null); p.rows.set(t, row); }
        row[i] = v;
        p.points += 1;
      }
      p.element.dataset.points = String(p.points);
    });
  }
}

// Redraws every plot ten times a second with the points inside its time window (while the
// plots are shown; older points are dropped either way).
setInterval(() => {
  if (paused) return;
  const window = Number($('plot-window').value);
  const now = Date.now() / 1000;
  const visible = shown('plots');
  for (const p of plots) {
    if (!p.plot) continue;
    for (const t of p.rows.keys()) if (t < now - window - 1) p.rows.delete(t);
    if (!visible) continue;
    const times = [...p.rows.keys()].sort((a, b) => a - b);
    const data = [times, ...p.series.map((_, i) => times.map((t) => p.rows.get(t)[i]))];
    p.plot.setData(data);
  }
}, 100);

connect();
