// The replay control: the hub Thing's ``replay`` / ``stopReplay`` actions, invoked through the
// forms of its TD. Play shows the replay Thing (replay-<device>) in place of the live device;
// pause stops the replay and remembers the recorded time of the last packet shown, so play
// continues from there; live goes back to the device.

import {invokeAction} from "./wot.js";

const $ = (id) => document.getElementById(id);

export class ReplayControl {
  constructor(hubTd, device, cb) {
    this.hub = hubTd;
    this.device = device;
    this.cb = cb;
    this.thing = null; // the replay Thing while one runs or is paused
    this.paused = false;
    this.resumeFrom = null; // seconds since the epoch
    this.range = {};
    this.state = (window.twin.replay = {state: "idle", thing: null, error: null, range: null});
    $("range").onchange = () => ($("custom-range").hidden = $("range").value !== "custom");
    $("play").onclick = () => this.run(() => this.play());
    $("pause").onclick = () => this.run(() => this.pause());
    $("live").onclick = () => this.run(() => this.live());
    if (!device) this.status("this device is not served by this hub: nothing to replay");
    $("play").disabled = !device;
  }

  async run(step) {
    for (const b of ["play", "pause", "live"]) $(b).disabled = true;
    try {
      await step();
      this.state.error = null;
    } catch (e) {
      this.state.error = String(e.message || e);
      this.status(this.state.error);
    }
    $("play").disabled = !this.device || (this.thing !== null && !this.paused);
    $("pause").disabled = this.thing === null || this.paused;
    $("live").disabled = this.thing === null;
  }

  input() {
    const input = {device: this.device, speed: Number($("speed").value), loop: $("loop").checked};
    if (this.paused && this.resumeFrom !== null) {
      input.from = this.resumeFrom;
      if (this.range.to !== undefined) input.to = this.range.to;
    } else if ($("range").value === "custom") {
      const from = Date.parse($("from").value), to = Date.parse($("to").value); // local time
      if (!Number.isNaN(from)) input.from = from / 1000;
      if (!Number.isNaN(to)) input.to = to / 1000;
    } else {
      input.from = $("range").value; // "-30s": the hub reads it relative to its clock
    }
    // the TD declares from/to as strings (a number as text is seconds, or ns above 1e14)
    for (const k of ["from", "to"]) if (typeof input[k] === "number") input[k] = String(input[k]);
    return input;
  }

  async play() {
    const input = this.input();
    const out = await invokeAction(this.hub, "replay", input);
    this.thing = out.thing;
    this.range = {from: out.from, to: out.to};
    this.paused = false;
    this.resumeFrom = null;
    Object.assign(this.state, {state: "playing", thing: out.thing, range: this.range});
    await this.cb.show(out.td, out.after);
    this.cb.setMode("replay");
    const when = (ns) => (ns === undefined ? "…" : new Date(ns / 1e6).toLocaleTimeString());
    this.status(`${out.thing}: ${when(out.from)} → ${when(out.to)} at ${out.speed}×${out.loop ? ", loop" : ""}`);
  }

  async pause() {
    const stamp = this.cb.lastStamp(); // ms, recorded time of the last packet shown
    await invokeAction(this.hub, "stopReplay", {thing: this.thing});
    this.cb.detach();
    this.paused = true;
    this.resumeFrom = stamp !== null ? (stamp + 0.001) / 1000 : (this.range.from ?? null);
    Object.assign(this.state, {state: "paused"});
    this.cb.setMode("paused");
    this.status(stamp !== null ? `paused at ${new Date(stamp).toLocaleTimeString()}` : "paused");
  }

  async live() {
    if (this.thing !== null && !this.paused) await invokeAction(this.hub, "stopReplay", {thing: this.thing});
    this.thing = null;
    this.paused = false;
    this.resumeFrom = null;
    Object.assign(this.state, {state: "idle", thing: null});
    await this.cb.live();
    this.cb.setMode("live");
    this.status("");
  }

  status(text) {
    $("replay-status").textContent = text;
  }
}
