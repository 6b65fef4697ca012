// teleprev's XR page: streams WebXR hand joints and the headset pose to teleprev over a WebSocket
// (the binary layout is devices/teleprev_devices/webxr/wire.py), shows the session's status in the
// headset, and sends the operator's actions (pinch gestures, controller buttons, the buttons on the page).
"use strict";

const JOINTS = ["wrist",
  "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip",
  ...["index-finger", "middle-finger", "ring-finger", "pinky-finger"].flatMap(f =>
    ["metacarpal", "phalanx-proximal", "phalanx-intermediate", "phalanx-distal", "tip"].map(p => `${f}-${p}`))];
const HEADER_BYTES = 28, FLOATS = 7 + 2 * 25 * 8, FRAME_BYTES = HEADER_BYTES + 4 * FLOATS;
const HEADSET = 1, LEFT = 2, RIGHT = 4;
const PINCH_ON_M = 0.015, PINCH_OFF_M = 0.03;  // thumb tip to finger tip: closes below, opens above

const params = new URLSearchParams(location.search);
const token = params.get("token") || "";
const keepLog = params.get("log") === "1";  // tests and benchmarks read back what the page sent

const state = {
  ws: null, connected: false, status: null, seq: 0, sent: 0, session: null, refSpace: null,
  gl: null, panel: null, pinch: { index: false, middle: false }, lastAck: null,
};
// What the page sent, for tests (only with ?log=1): one Float32Array of FLOATS per frame, and its header.
window.teleprev = { log: [], heads: [], state, actions: [] };

// ---- the connection ------------------------------------------------------------------------------
function connect() {
  const url = `wss://${location.host}/ws` + (token ? `?token=${encodeURIComponent(token)}` : "");
  const ws = new WebSocket(url);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => {
    state.connected = true;
    ws.send(JSON.stringify({ type: "hello", agent: navigator.userAgent, session: state.session ? state.session.mode : "" }));
    render();
  };
  ws.onmessage = ev => {
    if (typeof ev.data !== "string") return;
    const msg = JSON.parse(ev.data);
    if (msg.type === "status") state.status = msg;
    else if (msg.type === "ack") state.lastAck = msg;
    render();
  };
  ws.onclose = () => {
    state.connected = false;
    state.ws = null;
    render();
    setTimeout(connect, 500);  // teleprev restarted (a new recording, devices check): find it again
  };
  state.ws = ws;
}

// `via`: "gesture" for a pinch (a recording whose left hand drives a robot refuses those; its status says
// gestures: false, and the page then stops reading pinches at all).
function act(action, via = "") {
  window.teleprev.actions.push(action);
  if (state.ws && state.connected) state.ws.send(JSON.stringify({ type: "action", action, via }));
}

function episodeAction() {
  return state.status && state.status.episode_active ? "stop" : "start";
}

// ---- one XR frame on the wire ----------------------------------------------------------------------
function packFrame(frame, time) {
  const buffer = new ArrayBuffer(FRAME_BYTES);
  const view = new DataView(buffer);
  const values = new Float32Array(buffer, HEADER_BYTES, FLOATS);
  let present = 0;
  const viewer = frame.getViewerPose(state.refSpace);
  if (viewer) {
    present |= HEADSET;
    putPose(values, 0, viewer.transform);
  }
  const hands = {};
  for (const source of frame.session.inputSources) {
    if (!source.hand || (source.handedness !== "left" && source.handedness !== "right")) continue;
    const offset = source.handedness === "left" ? 7 : 207;
    let tracked = true;
    for (let j = 0; j < JOINTS.length && tracked; j++) {
      const pose = frame.getJointPose(source.hand.get(JOINTS[j]), state.refSpace);
      if (!pose) { tracked = false; break; }
      putPose(values, offset + 8 * j, pose.transform);
      values[offset + 8 * j + 7] = pose.radius;
    }
    if (tracked) {
      present |= source.handedness === "left" ? LEFT : RIGHT;
      hands[source.handedness] = values.subarray(offset, offset + 200);
    } else {
      values.fill(0, offset, offset + 200);  // a hand out of view: not sent (the robot holds)
    }
  }
  const frameMs = performance.timeOrigin + time;
  const sentMs = performance.timeOrigin + performance.now();
  view.setUint8(0, 0x54); view.setUint8(1, 0x50); view.setUint8(2, 0x58); view.setUint8(3, 0x52);  // "TPXR"
  view.setUint16(4, 1, true);
  view.setUint8(6, present);
  view.setUint8(7, 0);
  view.setUint32(8, state.seq >>> 0, true);
  view.setFloat64(12, frameMs, true);
  view.setFloat64(20, sentMs, true);
  return { buffer, values, present, hands, sentMs };
}

function putPose(values, at, transform) {
  const p = transform.position, q = transform.orientation;
  values[at] = p.x; values[at + 1] = p.y; values[at + 2] = p.z;
  values[at + 3] = q.x; values[at + 4] = q.y; values[at + 5] = q.z; values[at + 6] = q.w;
}

// ---- gestures: the left hand's pinches ---------------------------------------------------------------
function tip(hand, name) { const k = 8 * JOINTS.indexOf(name); return [hand[k], hand[k + 1], hand[k + 2]]; }
function distance(a, b) { return Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]); }

function gestures(left) {
  const off = state.status && state.status.gestures === false;  // both hands drive robots (a bimanual rig)
  if (!left || off) { state.pinch.index = state.pinch.middle = false; return; }
  const thumb = tip(left, "thumb-tip");
  for (const [finger, action] of [["index", () => "toggle_mode"], ["middle", episodeAction]]) {
    const d = distance(thumb, tip(left, `${finger}-finger-tip`));
    if (!state.pinch[finger] && d < PINCH_ON_M) { state.pinch[finger] = true; act(action(), "gesture"); }
    else if (state.pinch[finger] && d > PINCH_OFF_M) state.pinch[finger] = false;
  }
}

// ---- the XR session -----------------------------------------------------------------------------------
async function enterXR(mode) {
  if (!navigator.xr) { setNote("this browser has no WebXR (open the page in the headset's browser)"); return; }
  if (!(await navigator.xr.isSessionSupported(mode))) { setNote(`${mode} is not supported here`); return; }
  const canvas = document.getElementById("gl");
  const gl = canvas.getContext("webgl", { xrCompatible: true, alpha: true });
  const session = await navigator.xr.requestSession(mode, { optionalFeatures: ["local-floor", "hand-tracking"] });
  state.session = session;
  state.gl = gl;
  session.updateRenderState({ baseLayer: new XRWebGLLayer(session, gl) });
  // The floor frame where the headset has one; "local" (origin at the head's start) otherwise: teleprev
  // follows the wrist's motion, and its yaw comes from calibration, so either frame drives the robot alike.
  state.refSpace = await session.requestReferenceSpace("local-floor").catch(() => session.requestReferenceSpace("local"));
  state.panel = makePanel(gl);
  session.addEventListener("select", ev => { if (!ev.inputSource.hand) act("toggle_mode"); });
  session.addEventListener("squeeze", ev => { if (!ev.inputSource.hand) act(episodeAction()); });
  session.addEventListener("end", () => { state.session = null; render(); });
  if (state.ws && state.connected) state.ws.send(JSON.stringify({ type: "hello", agent: navigator.userAgent, session: mode }));
  session.requestAnimationFrame(onFrame);
  render();
}

function onFrame(time, frame) {
  const session = frame.session;
  session.requestAnimationFrame(onFrame);
  const packed = packFrame(frame, time);
  if (state.ws && state.connected) {
    // A frame the socket has no room for is skipped, not queued (stale hands are worse than none); its
    // sequence number is still used, so that teleprev counts it as lost.
    if (state.ws.bufferedAmount < 64 * FRAME_BYTES) {
      state.ws.send(packed.buffer);
      state.sent++;
      if (keepLog) {
        window.teleprev.log.push(packed.values.slice());
        window.teleprev.heads.push({ seq: state.seq, present: packed.present, sent_ms: packed.sentMs });
      }
    }
    state.seq++;
  }
  gestures(packed.hands.left);
  drawPanel(frame);
}

// ---- the status panel, in the page and in the headset ---------------------------------------------------
function statusLines() {
  const s = state.status;
  const lines = [state.connected ? "connected to teleprev" : "not connected: is teleprev running?"];
  if (s && s.recording) {
    lines.push(`${(s.mode || "preview").toUpperCase()}`);
    lines.push(s.episode_active ? `episode ${s.episode} (${s.task || "task"})` : `no episode (${s.episode + 1} recorded)`);
    lines.push(s.corrected_links && s.corrected_links.length ? `corrected: ${s.corrected_links.join(", ")}` : "corrected: none");
    if (s.message) lines.push(s.message);
  } else if (s) {
    lines.push("not recording (devices check or calibrate)");
  }
  if (s && s.refused_connections) lines.push(`refused connections: ${s.refused_connections}`);
  if (state.lastAck && state.lastAck.refused) lines.push(`${state.lastAck.action}: ${state.lastAck.refused}`);
  return lines;
}

let note = "";
function setNote(text) { note = text; render(); }

function render() {
  const el = document.getElementById("status");
  const lines = statusLines();
  if (note) lines.push(note);
  el.textContent = lines.join("\n");
  el.className = state.status && state.status.mode === "execute" ? "execute" : "preview";
  if (state.panel) state.panel.dirty = true;
}

function makePanel(gl) {
  const canvas = document.createElement("canvas");
  canvas.width = 512; canvas.height = 256;
  const vs = "attribute vec2 p; uniform mat4 m; varying vec2 uv; void main(){ uv = vec2(p.x + 0.5, 0.5 - p.y); gl_Position = m * vec4(p.x * 0.3, p.y * 0.15, 0.0, 1.0); }";
  const fs = "precision mediump float; uniform sampler2D t; varying vec2 uv; void main(){ gl_FragColor = texture2D(t, uv); }";
  const program = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const shader = gl.createShader(type);
    gl.shaderSource(shader, src); gl.compileShader(shader); gl.attachShader(program, shader);
  }
  gl.linkProgram(program);
  const buffer = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-0.5, -0.5, 0.5, -0.5, -0.5, 0.5, 0.5, 0.5]), gl.STATIC_DRAW);
  return { canvas, program, buffer, texture: gl.createTexture(), dirty: true };
}

function drawPanel(frame) {
  const gl = state.gl, panel = state.panel, layer = frame.session.renderState.baseLayer;
  const viewer = frame.getViewerPose(state.refSpace);
  gl.bindFramebuffer(gl.FRAMEBUFFER, layer.framebuffer);
  gl.clearColor(0, 0, 0, 0);
  gl.clear(gl.COLOR_BUFFER_BIT);
  if (!viewer) return;
  if (panel.dirty) {
    const ctx = panel.canvas.getContext("2d");
    ctx.fillStyle = "rgba(20,20,20,0.85)"; ctx.fillRect(0, 0, 512, 256);
    ctx.font = "28px sans-serif";
    statusLines().forEach((line, k) => {
      ctx.fillStyle = k === 1 && /EXECUTE/.test(line) ? "#ff5555" : "#eeeeee";
      ctx.fillText(line.slice(0, 34), 16, 40 + 44 * k);
    });
    gl.bindTexture(gl.TEXTURE_2D, panel.texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, panel.canvas);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    panel.dirty = false;
  }
  // The panel hangs 0.6 m ahead of the eyes and 0.25 m below, following the head.
  const model = multiply(viewer.transform.matrix, translation(0, -0.25, -0.6));
  gl.useProgram(panel.program);
  gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
  gl.bindBuffer(gl.ARRAY_BUFFER, panel.buffer);
  const at = gl.getAttribLocation(panel.program, "p");
  gl.enableVertexAttribArray(at);
  gl.vertexAttribPointer(at, 2, gl.FLOAT, false, 0, 0);
  gl.bindTexture(gl.TEXTURE_2D, panel.texture);
  for (const view of viewer.views) {
    const vp = layer.getViewport(view);
    gl.viewport(vp.x, vp.y, vp.width, vp.height);
    const m = multiply(view.projectionMatrix, multiply(view.transform.inverse.matrix, model));
    gl.uniformMatrix4fv(gl.getUniformLocation(panel.program, "m"), false, m);
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
  }
}

function translation(x, y, z) { return new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, y, z, 1]); }
function multiply(a, b) {  // column-major 4x4: a * b
  const out = new Float32Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let s = 0;
    for (let k = 0; k < 4; k++) s += a[4 * k + r] * b[4 * c + k];
    out[4 * c + r] = s;
  }
  return out;
}

document.getElementById("enter-ar").onclick = () => enterXR("immersive-ar").catch(e => setNote(`cannot enter XR: ${e}`));
document.getElementById("enter-vr").onclick = () => enterXR("immersive-vr").catch(e => setNote(`cannot enter XR: ${e}`));
document.getElementById("toggle-mode").onclick = () => act("toggle_mode");
document.getElementById("episode").onclick = () => act(episodeAction());
connect();
render();
