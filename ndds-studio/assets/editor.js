// ndds studio: the editor (ControlShell's Data-Flow Editor and FSM editor) over description
// files. Every change is one `edit` request; the studio applies it to the file's TOML (keeping
// its layout), checks the whole system with the loader `ndds run` uses, and answers with the
// editor's state: the files, the loader's problems (each tied to an element), the diff.
'use strict';

const ed = {
  state: null,      // the editor's state as the studio sends it
  palette: null,    // {components: [{name, summary, params}], sections}
  selected: null,   // {file, index} of the component in the inspector
  adding: null,     // the library type being added
  connecting: null, // {from, to}: drawing a connection on the diagram
  listed: false,
};
graphs.ed = cytoscape({ container: $('ed-graph'), style: graphStyle, wheelSensitivity: 0.3 });
graphs.edFsm = cytoscape({ container: $('ed-fsm-graph'), style: graphStyle, wheelSensitivity: 0.3 });

function edit(op, after) {
  $('ed-save-anyway').hidden = true;
  const id = state.nextId++;
  state.replies[`edit${id}`] = after;
  send({ type: 'edit', id, op });
}

function editorMessage(m) {
  if (m.palette) { ed.palette = m.palette; renderPalette(); }
  const after = state.replies[`edit${m.id}`];
  delete state.replies[`edit${m.id}`];
  if (m.state) { ed.state = m.state; renderEditor(); }
  if (after) after(m.ok, m.text);
  else showReply('ed-reply', m.ok, m.text);
}

function editorShown() {
  if (ed.listed) return;
  ed.listed = true;
  listFiles();
}
function listFiles() {
  edit({ op: 'list' }, (ok, text) => {
    if (!ok) { showReply('ed-reply', false, text); ed.listed = false; return; }
    fillSelect($('ed-files'), text ? text.split('\n') : []);
  });
}

// TOML text of a value the user typed: names of CSMats, texts and files get their quotes.
function tomlText(kind, text) {
  const t = text.trim();
  if (t === '') return null;
  if (['input', 'output', 'text', 'file'].includes(kind) && !t.startsWith('"')) return JSON.stringify(t);
  if (kind === 'inputs' && !t.startsWith('[')) return `[${t.split(/\s*,\s*/).filter(Boolean).map((x) => JSON.stringify(x)).join(', ')}]`;
  return t;
}
function tomlList(names) {
  return `[${names.map((x) => JSON.stringify(x)).join(', ')}]`;
}
function listText(text) {
  return tomlList(text.split(/\s*,\s*/).filter(Boolean));
}

// ---- the model: what the files declare ------------------------------------------------------
function descriptionFiles() {
  return ed.state ? ed.state.files.filter((f) => f.kind === 'description') : [];
}
function entries(section) {
  const out = [];
  for (const f of descriptionFiles()) {
    if (!f.data || !Array.isArray(f.data[section])) continue;
    f.data[section].forEach((data, index) => {
      const texts = (f.values && f.values[section] && f.values[section][index]) || {};
      out.push({ file: f.path, index, data, texts });
    });
  }
  return out;
}
function specOf(type) {
  return ed.palette ? ed.palette.components.find((c) => c.name === type) : null;
}
function matsOf(c, kinds) {
  const spec = specOf(c.data.type);
  if (!spec) return [];
  const out = [];
  for (const p of spec.params) {
    if (!kinds.includes(p.kind)) continue;
    const v = c.data[p.name];
    if (typeof v === 'string') out.push(v);
    else if (Array.isArray(v)) for (const x of v) if (typeof x === 'string') out.push(x);
  }
  return out;
}
function problemsAt(file, path) {
  if (!ed.state) return [];
  return ed.state.problems.filter((p) => p.file === file && path.every((step, i) => p.path[i] === step));
}
function knownMats() {
  const names = new Set();
  for (const m of entries('mat')) if (m.data.name) names.add(m.data.name);
  for (const s of entries('subscribe')) if (s.data.mat) names.add(s.data.mat);
  for (const c of entries('component')) for (const n of matsOf(c, ['output', 'input', 'inputs'])) names.add(n);
  return [...names].sort();
}
function knownGroups() {
  const names = new Set();
  for (const c of entries('component')) if (c.data.group) names.add(c.data.group);
  for (const c of entries('configuration')) for (const g of c.data.groups || []) names.add(g);
  return [...names].sort();
}
function groupColourOf(group) {
  const i = knownGroups().indexOf(group);
  return palette[(i < 0 ? 0 : i) % palette.length];
}

// ---- drawing ------------------------------------------------------------------------------
function renderEditor() {
  const s = ed.state;
  const verdict = $('ed-verdict');
  if (!s || !s.top) { verdict.textContent = ''; return; }
  verdict.textContent = s.ok ? `✓ ${s.summary}` : `✗ ${s.problems.length} problem${s.problems.length === 1 ? '' : 's'}`;
  verdict.className = 'verdict ' + (s.ok ? 'ok' : 'bad');
  renderFlow();
  renderComponentTable();
  renderHabitatTable();
  renderConfigTable();
  renderMachines();
  renderProblems();
  renderDiff();
  renderTextBox();
  renderInspector();
}

// The data-flow diagram: one row per habitat, components in execution order (the loader's,
// when the system verifies), coloured by group; subscribed topics and declared CSMats feed
// the components that read them.
function renderFlow() {
  const comps = entries('component');
  const habitats = entries('habitat').map((h) => h.data.name).filter(Boolean);
  for (const c of comps) if (c.data.habitat && !habitats.includes(c.data.habitat)) habitats.push(c.data.habitat);
  const elements = [];
  const position = {};
  const writers = {};
  for (const c of comps) for (const m of matsOf(c, ['output'])) (writers[m] = writers[m] || []).push(c);
  habitats.forEach((h, row) => {
    const rate = entries('habitat').find((x) => x.data.name === h);
    elements.push({ group: 'nodes', data: { id: `hab:${h}`, label: `${h}${rate && rate.data.rate ? `\n${rate.data.rate} Hz` : ''}` }, position: { x: -380, y: 130 * row }, classes: 'habitat' });
    const order = (ed.state.orders && ed.state.orders[h]) || [];
    const members = comps.filter((c) => c.data.habitat === h).map((c) => c.data.name);
    const ordered = order.filter((n) => members.includes(n)).concat(members.filter((n) => !order.includes(n)));
    ordered.forEach((name, col) => { position[name] = { x: 170 * col, y: 130 * row }; });
  });
  const keyOf = (c) => `comp:${c.file}:${c.index}`;
  comps.forEach((c) => {
    const data = { id: keyOf(c), label: `${c.data.name || '?'}\n${c.data.type || '?'}`, file: c.file, index: c.index };
    if (c.data.group) data.colour = groupColourOf(c.data.group);
    const bad = problemsAt(c.file, ['component', c.index]).length > 0;
    elements.push({ group: 'nodes', data, position: position[c.data.name] || { x: 170 * c.index, y: 130 * habitats.length }, classes: bad ? 'problem' : '' });
  });
  const readersOf = (mat) => comps.filter((c) => matsOf(c, ['input', 'inputs']).includes(mat));
  const seen = new Set();
  const edge = (source, target, label) => {
    const id = `${source}>${target}:${label}`;
    if (seen.has(id)) return;
    seen.add(id);
    elements.push({ group: 'edges', data: { id, source, target, label } });
  };
  for (const c of comps) for (const mat of matsOf(c, ['input', 'inputs'])) for (const w of writers[mat] || []) edge(keyOf(w), keyOf(c), mat);
  // Sources: subscribed topics (in their habitat's row) and declared CSMats (below).
  const subs = entries('subscribe');
  subs.forEach((sub, i) => {
    const row = Math.max(0, habitats.indexOf(sub.data.habitat));
    const id = `sub:${sub.file}:${sub.index}`;
    elements.push({ group: 'nodes', data: { id, label: `${sub.data.topic}\n→ ${sub.data.mat}` }, position: { x: -190, y: 130 * row + 40 * (i % 3) - 40 }, classes: 'source' });
    for (const r of readersOf(sub.data.mat)) edge(id, keyOf(r), sub.data.mat);
  });
  entries('mat').forEach((m, i) => {
    const id = `mat:${m.file}:${m.index}`;
    elements.push({ group: 'nodes', data: { id, label: `${m.data.name}\n(reference)` }, position: { x: -190 + 150 * i, y: 130 * habitats.length + 60 }, classes: 'source' });
    for (const r of readersOf(m.data.name)) edge(id, keyOf(r), m.data.name);
  });
  entries('publish').forEach((p) => {
    const id = `pub:${p.file}:${p.index}`;
    const from = writers[p.data.mat] || [];
    const row = Math.max(0, habitats.indexOf(p.data.habitat));
    const last = Math.max(0, ...Object.values(position).filter((x) => x.y === 130 * row).map((x) => x.x));
    elements.push({ group: 'nodes', data: { id, label: `${p.data.mat}\n→ ${p.data.topic}` }, position: { x: last + 190, y: 130 * row + 40 }, classes: 'source' });
    for (const w of from) edge(keyOf(w), id, p.data.mat);
  });
  setElements(graphs.ed, elements, JSON.stringify([elements, ed.state.problems]), { name: 'preset', padding: 30 });
  graphs.ed.nodes().unselect();
  if (ed.selected) graphs.ed.getElementById(`comp:${ed.selected.file}:${ed.selected.index}`).select();
  $('ed-legend').replaceChildren(...knownGroups().map((g) => el('span', {},
    el('span', { class: 'swatch', style: `background:${groupColourOf(g)}` }), g)));
}
graphs.ed.on('tap', 'node', (event) => {
  const file = event.target.data('file');
  if (file === undefined) return;
  const index = event.target.data('index');
  // Connecting: the first component tapped writes, the second reads.
  if (ed.connecting && ed.connecting.from && !(ed.connecting.from.file === file && ed.connecting.from.index === index)) {
    ed.connecting.to = { file, index };
    ed.selected = { file, index };
    renderInspector();
    return;
  }
  if (ed.connecting) ed.connecting.from = { file, index };
  selectComponent(file, index);
});
$('ed-connect').addEventListener('click', () => {
  ed.connecting = ed.connecting ? null : { from: null };
  $('ed-connect').classList.toggle('active', !!ed.connecting);
  showReply('ed-reply', true, ed.connecting ? 'connect: tap the component that writes, then the one that reads' : '');
});

// The connection form: one of the writer's outputs to one of the reader's inputs.
function renderConnecting(box) {
  const find = (at) => entries('component').find((x) => x.file === at.file && x.index === at.index);
  const from = find(ed.connecting.from);
  const to = find(ed.connecting.to);
  const fromSpec = from && specOf(from.data.type);
  const toSpec = to && specOf(to.data.type);
  if (!from || !to || !fromSpec || !toSpec) { ed.connecting = null; renderInspector(); return; }
  const outputs = matsOf(from, ['output']);
  const inputs = toSpec.params.filter((p) => p.kind === 'input' || p.kind === 'inputs');
  const mat = el('select', { id: 'ed-connect-mat' }, ...outputs.map((m) => el('option', { value: m }, m)));
  const key = el('select', { id: 'ed-connect-key' }, ...inputs.map((p) => el('option', { value: p.name }, `${p.name} (${p.kind === 'inputs' ? 'adds to the list' : p.doc})`)));
  box.replaceChildren(
    el('h3', {}, `Connect ${from.data.name} → ${to.data.name}`),
    outputs.length && inputs.length ? el('p', {}, 'output ', mat, ' to input ', key) : el('p', { class: 'field-problem' }, outputs.length ? `${to.data.type} reads no CSMat` : `${from.data.name} writes no CSMat yet: give it an output first`),
    el('button', { id: 'ed-connect-apply', onclick: () => {
      const spec = inputs.find((p) => p.name === key.value);
      if (!spec || !mat.value) return;
      let value = JSON.stringify(mat.value);
      if (spec.kind === 'inputs') {
        const have = Array.isArray(to.data[spec.name]) ? to.data[spec.name] : [];
        value = `[${have.concat(have.includes(mat.value) ? [] : [mat.value]).map((x) => JSON.stringify(x)).join(', ')}]`;
      }
      const target = ed.connecting.to;
      ed.connecting = null;
      $('ed-connect').classList.remove('active');
      edit({ op: 'set', file: target.file, path: ['component', target.index, spec.name], value }, (ok, text) => {
        showReply('ed-reply', ok, ok ? `connected ${mat.value} to ${to.data.name}.${spec.name}` : text);
        if (ok) selectComponent(target.file, target.index);
      });
    } }, 'Connect'),
    el('button', { onclick: () => { ed.connecting = null; $('ed-connect').classList.remove('active'); renderInspector(); } }, 'Cancel'));
}

function selectComponent(file, index) {
  ed.selected = { file, index };
  ed.adding = null;
  renderInspector();
  renderComponentTable();
  graphs.ed.nodes().unselect();
  graphs.ed.getElementById(`comp:${file}:${index}`).select();
}

function renderComponentTable() {
  const body = $('ed-components').tBodies[0];
  body.replaceChildren(...entries('component').map((c) => {
    const classes = ['clickable'];
    if (problemsAt(c.file, ['component', c.index]).length) classes.push('problem');
    if (ed.selected && ed.selected.file === c.file && ed.selected.index === c.index) classes.push('selected');
    return el('tr', { class: classes.join(' '), 'data-component': c.data.name || '', onclick: () => selectComponent(c.file, c.index) },
      el('td', { class: 'mono' }, c.data.name || '?'), el('td', {}, c.data.type || '?'), el('td', {}, c.data.habitat || ''),
      el('td', {}, c.data.group || ''), el('td', { class: 'mono' }, matsOf(c, ['input', 'inputs']).join(', ')),
      el('td', { class: 'mono' }, matsOf(c, ['output']).join(', ')), el('td', { class: 'mono' }, c.file));
  }));
}

// The inspector: the selected component's keys (its type's documented parameters, inputs and
// outputs, and any other key written), each with the loader's problems at that key.
function renderInspector() {
  const box = $('ed-inspector');
  if (ed.adding) { renderAdding(box); return; }
  if (ed.connecting && ed.connecting.to) { renderConnecting(box); return; }
  const c = ed.selected && entries('component').find((x) => x.file === ed.selected.file && x.index === ed.selected.index);
  if (!c) {
    box.replaceChildren(el('p', { class: 'hint' }, ed.state && ed.state.top ? 'Click a component to edit it, or a type in the library to add one.' : 'Open a description file, or start a new one.'));
    return;
  }
  const spec = specOf(c.data.type);
  const path = (k) => ['component', c.index, k];
  const rows = [];
  const placedShown = new Set();
  // Each problem at the key it concerns: the key it was found at, or (for a key not written,
  // reported at the component's name) the key the message names.
  const keys = ['habitat', 'group'].concat(spec ? spec.params.map((p) => p.name) : [], Object.keys(c.texts));
  const placed = problemsAt(c.file, ['component', c.index]).map((p) => {
    const at = typeof p.path[2] === 'string' ? p.path[2] : null;
    const named = keys.find((k) => p.message.includes(`\`${k}\``));
    return [at && at !== 'name' ? at : (named || at), p];
  });
  const row = (key, kind, takes, doc, fallback, choices) => {
    const input = el('input', { 'data-key': key, value: c.texts[key] || '', placeholder: fallback ? `default ${fallback}` : (c.texts[key] === undefined && kind ? 'required' : ''), title: `${takes}${doc ? `: ${doc}` : ''}` });
    if (choices) input.setAttribute('list', choices);
    const problems = placed.filter(([k]) => k === key).map(([, p]) => p);
    for (const p of problems) placedShown.add(p);
    if (problems.length) input.classList.add('problem');
    const apply = () => {
      if (input.value === (c.texts[key] || '') || input.value === input.dataset.sent) return;
      input.dataset.sent = input.value;
      edit({ op: 'set', file: c.file, path: path(key), value: tomlText(kind, input.value) });
    };
    input.addEventListener('change', apply);
    input.addEventListener('keydown', (e) => { if (e.key === 'Enter') apply(); });
    rows.push(el('tr', { 'data-key': key },
      el('td', { class: 'mono', title: doc || '' }, key),
      el('td', {}, input, ...problems.map((p) => el('div', { class: 'field-problem' }, p.message)))));
  };
  row('name', 'text', 'the component\'s name', '', null, null);
  row('habitat', 'text', 'the habitat it runs in', '', null, 'ed-habitat-names');
  row('group', 'text', '"CATEGORY/GROUP" (configurations switch groups)', '', 'none', 'ed-group-names');
  const written = new Set(['name', 'type', 'habitat', 'group']);
  if (spec) {
    for (const p of spec.params) {
      written.add(p.name);
      const choices = ['input', 'inputs', 'output'].includes(p.kind) ? 'ed-mat-names' : null;
      row(p.name, p.kind, p.takes, p.doc, p.default, choices);
    }
  }
  for (const k of Object.keys(c.texts)) if (!written.has(k)) row(k, null, 'a key its type does not document', '', null, null);
  const general = problemsAt(c.file, ['component', c.index]).filter((p) => !placedShown.has(p));
  box.replaceChildren(
    el('h3', {}, `${c.data.name || '?'}: ${c.data.type || '?'}`),
    el('p', { class: 'hint' }, `${spec ? spec.summary : 'no documented parameters'} (${c.file})`),
    ...general.map((p) => el('div', { class: 'field-problem' }, p.message)),
    el('table', {}, el('tbody', {}, ...rows)),
    datalist('ed-mat-names', knownMats()), datalist('ed-habitat-names', entries('habitat').map((h) => h.data.name)),
    datalist('ed-group-names', knownGroups()),
    el('button', { id: 'ed-remove', onclick: () => { edit({ op: 'remove', file: c.file, path: ['component', c.index] }); ed.selected = null; } }, 'Remove this component'));
}
function datalist(id, names) {
  return el('datalist', { id }, ...names.filter(Boolean).map((n) => el('option', { value: n })));
}

// ---- the library palette -------------------------------------------------------------------
function renderPalette() {
  const filter = $('ed-palette-filter').value.trim().toLowerCase();
  $('ed-palette-list').replaceChildren(...ed.palette.components
    .filter((c) => !filter || c.name.includes(filter) || c.summary.toLowerCase().includes(filter))
    .map((c) => el('li', { title: c.summary, 'data-type': c.name, onclick: () => { ed.adding = c.name; renderInspector(); } }, c.name)));
}
$('ed-palette-filter').addEventListener('input', () => { if (ed.palette) renderPalette(); });

function renderAdding(box) {
  const spec = specOf(ed.adding);
  const files = descriptionFiles().map((f) => f.path);
  const name = el('input', { id: 'ed-add-name', placeholder: 'its name' });
  const habitat = el('select', { id: 'ed-add-habitat' }, ...entries('habitat').map((h) => el('option', { value: h.data.name }, h.data.name)));
  const file = el('select', { id: 'ed-add-file' }, ...files.map((f) => el('option', { value: f }, f)));
  if (ed.selected) file.value = ed.selected.file;
  box.replaceChildren(
    el('h3', {}, `Add a ${spec.name}`),
    el('p', {}, spec.summary),
    el('table', {}, el('tbody', {},
      el('tr', {}, el('td', {}, 'name'), el('td', {}, name)),
      el('tr', {}, el('td', {}, 'habitat'), el('td', {}, habitat)),
      el('tr', {}, el('td', {}, 'in file'), el('td', {}, file)))),
    el('button', { id: 'ed-add', onclick: () => {
      if (!ed.state || !ed.state.top) { showReply('ed-reply', false, 'open a description file, or start a new one, first'); return; }
      const fields = [['name', JSON.stringify(name.value.trim() || spec.name)], ['type', JSON.stringify(spec.name)]];
      if (habitat.value) fields.push(['habitat', JSON.stringify(habitat.value)]);
      const target = file.value;
      const index = entries('component').filter((c) => c.file === target).length;
      edit({ op: 'push', file: target, path: ['component'], fields }, (ok, text) => {
        showReply('ed-reply', ok, ok ? `added: now connect its inputs and outputs and give its parameters` : text);
        if (ok) { ed.adding = null; ed.selected = { file: target, index }; renderEditor(); }
      });
    } }, 'Add'),
    el('h3', {}, 'Its parameters'),
    el('table', {}, el('tbody', {}, ...spec.params.map((p) => el('tr', {},
      el('td', { class: 'mono' }, p.name), el('td', {}, p.kind), el('td', {}, p.default === null ? 'required' : `default ${p.default}`), el('td', {}, p.doc))))));
}

// ---- habitats and configurations --------------------------------------------------------------
function renderHabitatTable() {
  $('ed-habitats').tBodies[0].replaceChildren(...entries('habitat').map((h) => {
    const rate = el('input', { size: 8, value: h.texts.rate || '', 'data-habitat': h.data.name });
    rate.addEventListener('change', () => edit({ op: 'set', file: h.file, path: ['habitat', h.index, 'rate'], value: rate.value.trim() || null }));
    const bad = problemsAt(h.file, ['habitat', h.index]);
    return el('tr', { class: bad.length ? 'problem' : '' }, el('td', { class: 'mono' }, h.data.name || '?'), el('td', {}, rate),
      el('td', {}, h.data.clock || 'timer'), el('td', { class: 'mono' }, h.file),
      el('td', {}, el('button', { onclick: () => edit({ op: 'remove', file: h.file, path: ['habitat', h.index] }) }, 'remove')));
  }));
}
$('ed-hab-add').addEventListener('click', () => {
  const name = $('ed-hab-name').value.trim();
  const rate = $('ed-hab-rate').value.trim();
  if (!ed.state || !ed.state.top) return;
  const fields = [['name', JSON.stringify(name)]];
  if (rate) fields.push(['rate', rate]);
  edit({ op: 'push', file: ed.state.top, path: ['habitat'], fields });
});

function renderConfigTable() {
  $('ed-configs').tBodies[0].replaceChildren(...entries('configuration').map((c) => {
    const groups = el('input', { size: 40, value: (c.data.groups || []).join(', '), 'data-configuration': c.data.name });
    groups.addEventListener('change', () => edit({ op: 'set', file: c.file, path: ['configuration', c.index, 'groups'], value: listText(groups.value) }));
    const bad = problemsAt(c.file, ['configuration', c.index]);
    return el('tr', { class: bad.length ? 'problem' : '' }, el('td', { class: 'mono' }, c.data.name || '?'), el('td', {}, groups),
      el('td', { class: 'mono' }, c.file),
      el('td', {}, el('button', { onclick: () => edit({ op: 'remove', file: c.file, path: ['configuration', c.index] }) }, 'remove')));
  }));
}
$('ed-config-add').addEventListener('click', () => {
  if (!ed.state || !ed.state.top) return;
  const file = entries('configuration').length ? entries('configuration')[0].file : ed.state.top;
  edit({ op: 'push', file, path: ['configuration'], fields: [['name', JSON.stringify($('ed-config-name').value.trim())], ['groups', listText($('ed-config-groups').value)]] });
});

// ---- state machines (the FSM editor) ------------------------------------------------------------
function machineChoices() {
  const out = [];
  if (!ed.state) return out;
  for (const f of ed.state.files) {
    if (f.kind !== 'machine' || !f.data || !Array.isArray(f.data.machine)) continue;
    f.data.machine.forEach((m, index) => out.push({ key: `${f.path}#${index}`, file: f.path, index, data: m, program: f.data }));
  }
  return out;
}
$('ed-machine').addEventListener('input', renderMachines);
$('ed-machine-new').addEventListener('click', () => edit({ op: 'new_machine', name: $('ed-machine-name').value.trim() }));

function nextText(next) {
  if (typeof next === 'string') return JSON.stringify(next);
  return `{ ${Object.entries(next || {}).map(([k, v]) => `${k} = ${JSON.stringify(v)}`).join(', ')} }`;
}
function renderMachines() {
  const choices = machineChoices();
  fillSelect($('ed-machine'), choices.map((c) => c.key));
  const m = choices.find((c) => c.key === $('ed-machine').value) || choices[0];
  const panel = $('ed-fsm-panel');
  if (!m) {
    setElements(graphs.edFsm, [], 'none', { name: 'preset' });
    panel.replaceChildren(el('p', { class: 'hint' }, 'No state machine: add one (a file of its own, beside the top file).'));
    return;
  }
  const states = m.data.states || [];
  const transitions = m.data.transition || [];
  const elements = states.map((s) => ({ group: 'nodes', data: { id: `s:${s}`, label: s }, classes: s === m.data.start ? 'current' : '' }));
  transitions.forEach((t, i) => {
    let source = `s:${t.from}`;
    if (t.from === '*') { source = 'star'; if (!elements.some((e) => e.data.id === 'star')) elements.push({ group: 'nodes', data: { id: 'star', label: '*' }, classes: 'star' }); }
    const next = typeof t.next === 'string' ? { 0: t.next } : (t.next || {});
    for (const [code, to] of Object.entries(next)) {
      if (!elements.some((e) => e.data.id === `s:${to}`)) elements.push({ group: 'nodes', data: { id: `s:${to}`, label: `${to}?` }, classes: 'problem' });
      if (!elements.some((e) => e.data.id === source)) elements.push({ group: 'nodes', data: { id: source, label: `${t.from}?` }, classes: 'problem' });
      const action = t.action ? ` / ${t.action}` : '';
      elements.push({ group: 'edges', data: { id: `t:${i}:${code}`, source, target: `s:${to}`, label: `${t.when}${action}${Object.keys(next).length > 1 ? ` [${code}]` : ''}` } });
    }
  });
  setElements(graphs.edFsm, elements, JSON.stringify([m.key, m.data]), { name: 'breadthfirst', directed: true, padding: 30, spacingFactor: 1.3 });
  const at = (k) => ['machine', m.index].concat(k);
  const field = (value, path, size, kind) => {
    const input = el('input', { size, value });
    if (problemsAt(m.file, path).length) input.classList.add('problem');
    input.addEventListener('change', () => edit({ op: 'set', file: m.file, path, value: kind === 'raw' ? (input.value.trim() || null) : tomlText('text', input.value) }));
    return input;
  };
  const rows = transitions.map((t, i) => {
    const path = at(['transition', i]);
    const problems = problemsAt(m.file, path);
    return el('tr', { class: problems.length ? 'problem' : '', 'data-transition': String(i) },
      el('td', {}, field(t.from || '', path.concat('from'), 7)), el('td', {}, field(t.when || '', path.concat('when'), 14)),
      el('td', {}, field(t.action || '', path.concat('action'), 14)), el('td', {}, field(nextText(t.next), path.concat('next'), 20, 'raw')),
      el('td', {}, el('button', { onclick: () => edit({ op: 'remove', file: m.file, path }) }, '×'),
        ...problems.map((p) => el('div', { class: 'field-problem' }, p.message))));
  });
  const from = el('input', { size: 7, placeholder: 'from', id: 'ed-t-from' });
  const when = el('input', { size: 14, placeholder: 'when', id: 'ed-t-when' });
  const action = el('input', { size: 14, placeholder: 'action', id: 'ed-t-action' });
  const next = el('input', { size: 20, placeholder: 'next: State or 0=A, 1=B', id: 'ed-t-next' });
  const addTransition = () => {
    const pairs = next.value.includes('=') ? next.value.split(/\s*,\s*/).map((p) => p.split(/\s*=\s*/)) : [['0', next.value.trim()]];
    const fields = [['from', JSON.stringify(from.value.trim())], ['when', JSON.stringify(when.value.trim())]];
    if (action.value.trim()) fields.push(['action', JSON.stringify(action.value.trim())]);
    fields.push(['next', `{ ${pairs.map(([c, s]) => `${c} = ${JSON.stringify(s)}`).join(', ')} }`]);
    edit({ op: 'push', file: m.file, path: at(['transition']), fields });
  };
  const stateName = el('input', { size: 10, placeholder: 'state', id: 'ed-state-name' });
  const stimulusName = el('input', { size: 10, placeholder: 'stimulus', id: 'ed-stimulus-name' });
  const stimulusKind = el('select', {}, ...['transient', 'latched', 'condition'].map((k) => el('option', { value: k }, k)));
  const stimuli = Object.entries(m.program.stimuli || {});
  const general = problemsAt(m.file, []).filter((p) => p.path.length < 4);
  panel.replaceChildren(
    el('h3', {}, `${m.data.name} (${m.file})`),
    ...general.map((p) => el('div', { class: 'field-problem' }, p.message)),
    el('p', {}, 'states: ', states.map((s) => `${s}${s === m.data.start ? ' (start)' : ''}`).join(', ')),
    el('div', {}, stateName, el('button', { id: 'ed-state-add', onclick: () => edit({ op: 'set', file: m.file, path: at(['states']), value: tomlList(states.concat(stateName.value.trim())) }) }, 'add state'),
      el('button', { onclick: () => edit({ op: 'set', file: m.file, path: at(['states']), value: tomlList(states.filter((s) => s !== stateName.value.trim())) }) }, 'remove state')),
    el('p', {}, 'stimuli: ', stimuli.map(([k, v]) => `${k} (${v})`).join(', ') || 'none'),
    el('div', {}, stimulusName, stimulusKind, el('button', { onclick: () => edit({ op: 'set', file: m.file, path: ['stimuli', stimulusName.value.trim()], value: JSON.stringify(stimulusKind.value) }) }, 'add stimulus')),
    el('table', { id: 'ed-transitions' }, el('thead', {}, el('tr', {}, el('th', {}, 'from'), el('th', {}, 'when'), el('th', {}, 'action'), el('th', {}, 'next'), el('th', {}, ''))),
      el('tbody', {}, ...rows, el('tr', {}, el('td', {}, from), el('td', {}, when), el('td', {}, action), el('td', {}, next),
        el('td', {}, el('button', { id: 'ed-t-add', onclick: addTransition }, 'add'))))));
}

// ---- problems, diff, text ------------------------------------------------------------------------
function renderProblems() {
  $('ed-problems').replaceChildren(...ed.state.problems.map((p) => el('li', {
    onclick: () => {
      if (p.path[0] === 'component' && typeof p.path[1] === 'number') selectComponent(p.file, p.path[1]);
      else if (p.file) { $('ed-text-file').value = p.file; $('ed-text-box').open = true; renderTextBox(true); }
    },
  }, `${p.file || 'system'}${p.line ? `:${p.line}:${p.column}` : ''}: ${p.message}`)));
  if (!ed.state.problems.length) $('ed-problems').append(el('li', { class: 'hint' }, ed.state.ok ? 'none: the system verifies' : ''));
}
function renderDiff() {
  const pre = $('ed-diff');
  pre.replaceChildren(...(ed.state.diff || 'no unsaved changes').split('\n').map((line) =>
    el('span', { class: line.startsWith('+') && !line.startsWith('+++') ? 'add' : line.startsWith('-') && !line.startsWith('---') ? 'del' : '' }, `${line}\n`)));
}
function renderTextBox(force) {
  fillSelect($('ed-text-file'), ed.state.files.map((f) => f.path));
  const f = ed.state.files.find((x) => x.path === $('ed-text-file').value);
  if (f && (force || document.activeElement !== $('ed-text'))) $('ed-text').value = f.text;
}
$('ed-text-file').addEventListener('input', () => renderTextBox(true));
$('ed-text-apply').addEventListener('click', () => edit({ op: 'text', file: $('ed-text-file').value, text: $('ed-text').value }));

// ---- the toolbar -----------------------------------------------------------------------------------
// Opening another system forgets unsaved changes only when the user says so.
function unsavedOk() {
  const changed = ed.state ? ed.state.files.filter((f) => f.changed).map((f) => f.path) : [];
  return !changed.length || window.confirm(`Forget the unsaved changes in ${changed.join(', ')}?`);
}
$('ed-open').addEventListener('click', () => {
  if (!unsavedOk()) return;
  ed.selected = null;
  ed.adding = null;
  edit({ op: 'open', path: $('ed-files').value, discard: true });
});
$('ed-new').addEventListener('click', () => {
  if (!unsavedOk()) return;
  ed.selected = null;
  edit({ op: 'new', path: $('ed-new-path').value.trim(), discard: true }, (ok, text) => { showReply('ed-reply', ok, text); if (ok) listFiles(); });
});
const save = (force) => edit({ op: 'save', force }, (ok, text) => {
  showReply('ed-reply', ok, text);
  $('ed-save-anyway').hidden = ok || !text.includes('save anyway');
  if (ok) listFiles();
});
$('ed-save').addEventListener('click', () => save(false));
$('ed-save-anyway').addEventListener('click', () => save(true));
$('ed-revert').addEventListener('click', () => edit({ op: 'revert' }));
