// A Foxglove WebSocket client made by Foxglove (@foxglove/ws-protocol's FoxgloveClient, on the
// `ws` package), for interop-tests/tests/studio_foxglove.rs: connects to URL, subscribes to
// TOPIC, prints one JSON line per event (serverInfo, the channel, COUNT messages decoded as
// JSON), then checks that bad requests get status messages, and exits 0. Node finds the
// packages through NODE_PATH (.ci/run installs them into target/ci-node).
'use strict';
const { FoxgloveClient } = require('@foxglove/ws-protocol');
const WebSocket = require('ws');

const [url, topic, countText] = process.argv.slice(2);
const count = Number(countText || '10');
const say = (event) => console.log(JSON.stringify(event));
setTimeout(() => { say({ error: 'timed out' }); process.exit(2); }, 20000);

const client = new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
let received = 0;
let subscribed = false;
client.on('serverInfo', (info) => say({ serverInfo: info }));
client.on('error', (err) => { say({ error: String(err) }); process.exit(3); });
client.on('advertise', (channels) => {
  for (const channel of channels) {
    if (channel.topic === topic && !subscribed) {
      subscribed = true;
      say({ channel });
      client.subscribe(channel.id);
    }
  }
});
client.on('message', ({ timestamp, data }) => {
  received += 1;
  if (received > count) return;
  say({ message: JSON.parse(new TextDecoder().decode(data)), timestamp: String(timestamp) });
  if (received === count) {
    client.close();
    badRequests();
  }
});

// A raw connection: an unknown channel and an unsupported operation are answered with status
// messages, and the connection stays up.
function badRequests() {
  const raw = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  const statuses = [];
  raw.on('message', (data, binary) => {
    if (binary) return;
    const m = JSON.parse(data.toString());
    if (m.op === 'serverInfo') {
      raw.send(JSON.stringify({ op: 'subscribe', subscriptions: [{ id: 1, channelId: 999999 }] }));
      raw.send(JSON.stringify({ op: 'setParameters', parameters: [] }));
      raw.send('not json');
    } else if (m.op === 'status') {
      statuses.push(m);
      if (statuses.length === 3) {
        say({ statuses });
        raw.close();
        process.exit(0);
      }
    }
  });
}
