// Test-only, loaded after IWER's build/iwer.min.js (page.add_init_script): makes the page's browser a Meta
// Quest 3 with hand tracking, and plays a queue of recorded frames into it, one per XR frame.
//
//   window.xrPlayback.queue.push({right: {joints: [25 * 16], radii: [25]}, head: [x, y, z, qx, qy, qz, qw]})
//
// joints: column-major 4x4 matrices in the local-floor space, WebXR's joint order. A frame's entry is
// applied as the frame starts, before IWER computes the poses the page reads, so that XR frame N shows
// entry N. The left hand keeps IWER's own poses: `pinch` (0..1) closes thumb and index.
(() => {
  if (window !== window.top) return;
  const device = new IWER.XRDevice(IWER.metaQuest3, { stereoEnabled: true });
  device.installRuntime({ forceInstall: true });  // Chromium has a navigator.xr of its own
  device.primaryInputMode = "hand";
  device.position.set(0, 1.6, 0);
  const playback = { queue: [], played: 0, device };
  window.xrPlayback = playback;

  const SPACE = IWER.P_SPACE, JOINT = IWER.P_JOINT_SPACE;
  function playJoints(hand, joints, radii) {
    if (!hand.playing) {  // from now on the hand is what the recording says, not IWER's preset poses
      hand.playing = true;
      hand.updateHandPose = function () {};
      hand.position.set(0, 0, 0);
      hand.quaternion.set(0, 0, 0, 1);
    }
    let i = 0;
    for (const space of hand.inputSource.hand.values()) {
      const m = space[SPACE].offsetMatrix;
      for (let k = 0; k < 16; k++) m[k] = joints[16 * i + k];
      space[JOINT].radius = radii[i];
      i++;
    }
  }
  function apply(entry) {
    if (entry.head) {
      device.position.set(entry.head[0], entry.head[1], entry.head[2]);
      device.quaternion.set(entry.head[3], entry.head[4], entry.head[5], entry.head[6]);
    }
    for (const side of ["left", "right"]) {
      const e = entry[side], hand = device.hands[side];
      if (!e) continue;
      if (e.connected !== undefined) hand.connected = e.connected;
      if (e.pinch !== undefined) hand.setPinchValueImmediate(e.pinch);
      if (e.joints) playJoints(hand, e.joints, e.radii);
    }
  }
  playback.apply = apply;
  const inner = device[IWER.P_DEVICE];
  const frameStart = inner.onFrameStart;
  inner.onFrameStart = frame => {
    const entry = playback.queue.shift();
    if (entry) { apply(entry); playback.played++; }
    frameStart(frame);
  };
})();
