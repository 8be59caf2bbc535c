// cnc-hmi's 3D preview (three.js, served by cnc-hmi from the copy npm installed from
// services/hmi/three/package-lock.json; nothing comes from elsewhere): the loaded
// program's dry-run path (feeds solid, rapids dashed), the part already run drawn
// apart, the machine's travel as a box, the tool at the live position. Orbit, pan and
// zoom with a mouse or fingers (OrbitControls); view buttons top, front, side, iso.
// app.js drives it through window.preview3d; without WebGL it stays null and app.js
// draws its flat XY view instead.
import * as THREE from '/three/three.module.min.js';
import { OrbitControls } from '/three/OrbitControls.js';

const COLORS = { feed: 0x5b8fc7, rapid: 0xc9a227, done: 0x4bd16b, box: 0x55606c, tool: 0xff4b4b, play: 0x4bd16b };

class Preview3D {
  constructor(el) {
    this.el = el;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(0x0f1214);
    el.appendChild(this.renderer.domElement);
    this.renderer.domElement.id = 'preview3d-canvas';
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.1, 1e5);
    this.camera.up.set(0, 0, 1);  // Z up, as a mill's axes
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.enableDamping = false;
    this.controls.screenSpacePanning = true;
    this.controls.addEventListener('change', () => this.draw());
    // The origin's axes in grey: the path's colours stay the path's.
    const axes = new THREE.AxesHelper(20);
    axes.setColors(0x8a96a3, 0x8a96a3, 0x8a96a3);
    this.scene.add(axes);
    this.box = null; this.path = null; this.rapids = null; this.done = null; this.doneCount = 0;
    this.points = null; this.lines = null; this.progress = 0;
    this.tool = this.makeTool(6, 30);
    this.scene.add(this.tool);
    this.play = new THREE.Mesh(new THREE.SphereGeometry(2, 16, 12), new THREE.MeshBasicMaterial({ color: COLORS.play }));
    this.play.visible = false;
    this.scene.add(this.play);
    this.viewName = 'iso';
    this.frames = 0;
    this.pending = false;
    new ResizeObserver(() => this.resize()).observe(el);
    this.resize();
  }

  // A cylinder (the shank) on a cone (the cutting end), its tip at the origin, along +Z.
  makeTool(d, len) {
    const g = new THREE.Group();
    const mat = new THREE.MeshBasicMaterial({ color: COLORS.tool, transparent: true, opacity: 0.75 });
    const tip = new THREE.Mesh(new THREE.ConeGeometry(d / 2, d, 20), mat);
    tip.rotation.x = -Math.PI / 2; tip.position.z = d / 2;  // apex down at z = 0
    const shank = new THREE.Mesh(new THREE.CylinderGeometry(d / 2, d / 2, len, 20), mat);
    shank.rotation.x = Math.PI / 2; shank.position.z = d + len / 2;
    g.add(tip); g.add(shank);
    g.visible = false;
    return g;
  }

  resize() {
    const w = Math.max(this.el.clientWidth, 50), h = Math.max(this.el.clientHeight, 50);
    this.renderer.setSize(w, h, true);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.draw();
  }

  // Rendered once per animation frame at most, only when something changed.
  draw() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.renderer.render(this.scene, this.camera);
      this.frames++;
      window.hmiStats && (window.hmiStats.preview3dFrames = this.frames);
    });
  }

  // The machine's travel: a wire box from each axis's min to max (X, Y, Z).
  setTravel(axes) {
    const lim = ['X', 'Y', 'Z'].map((n) => axes.find((a) => a.name === n));
    if (lim.some((a) => !a)) return;
    if (this.box) this.scene.remove(this.box);
    const min = new THREE.Vector3(lim[0].min, lim[1].min, lim[2].min);
    const max = new THREE.Vector3(lim[0].max, lim[1].max, lim[2].max);
    this.travel = new THREE.Box3(min, max);
    this.box = new THREE.Box3Helper(this.travel, COLORS.box);
    this.scene.add(this.box);
    if (!this.points) this.setView(this.viewName);
    this.draw();
  }

  // The dry run's points [x,y,z,...], rapid[i] = 1 where point i ends a rapid move.
  setPath(points, rapid, lines) {
    for (const o of [this.path, this.rapids, this.done]) if (o) { this.scene.remove(o); o.geometry.dispose(); }
    this.path = this.rapids = this.done = null;
    this.points = points && points.length >= 6 ? points : null;
    this.lines = lines || null;
    this.progress = 0; this.doneCount = 0;
    if (this.points) {
      const feed = [], fast = [], all = new Float32Array(Math.max(0, points.length - 3) * 2);
      for (let i = 3, k = 0; i < points.length; i += 3, k += 6) {
        const seg = [points[i - 3], points[i - 2], points[i - 1], points[i], points[i + 1], points[i + 2]];
        ((rapid && rapid[i / 3]) ? fast : feed).push(...seg);
        all.set(seg, k);
      }
      const lineSet = (arr, mat) => {
        const g = new THREE.BufferGeometry();
        g.setAttribute('position', new THREE.Float32BufferAttribute(arr, 3));
        const o = new THREE.LineSegments(g, mat);
        if (mat.isLineDashedMaterial) o.computeLineDistances();
        this.scene.add(o);
        return o;
      };
      this.path = lineSet(feed, new THREE.LineBasicMaterial({ color: COLORS.feed }));
      this.rapids = lineSet(fast, new THREE.LineDashedMaterial({ color: COLORS.rapid, dashSize: 2, gapSize: 1.5 }));
      // The part already run: the same segments, in order, shown up to the progress.
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(all, 3));
      g.setDrawRange(0, 0);
      this.done = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: COLORS.done, depthFunc: THREE.LessEqualDepth }));
      this.done.renderOrder = 1;
      this.scene.add(this.done);
    }
    this.setView(this.viewName);
  }

  // How far along the path the machine is: the nearest point ahead of the last one
  // (within 2000 points, on the running line when it is known), never going back.
  follow(pos, line, running) {
    const p = this.points;
    if (!p || !this.done || !running) return;
    const n = p.length / 3;
    let best = -1, bestD = Infinity, onLine = false;
    for (let i = this.progress; i < Math.min(n, this.progress + 2000); i++) {
      const here = line > 0 && this.lines && this.lines[i] === line;
      if (onLine && !here) continue;  // a point of the running line beats any other
      const d = Math.abs(p[3 * i] - pos[0]) + Math.abs(p[3 * i + 1] - pos[1]) + Math.abs(p[3 * i + 2] - pos[2]);
      if ((here && !onLine) || d < bestD) { bestD = d; best = i; onLine = here; }
    }
    if (best > this.progress && bestD < 3) this.setProgress(best);
  }

  setProgress(i) {
    this.progress = i;
    this.doneCount = i;
    if (this.done) this.done.geometry.setDrawRange(0, 2 * i);
    window.hmiStats && (window.hmiStats.preview3dDone = i);
    this.draw();
  }

  setTool(pos) {
    if (!pos) { this.tool.visible = false; this.draw(); return; }
    this.tool.visible = true;
    this.tool.position.set(pos[0], pos[1], pos[2]);
    this.draw();
  }

  setPlay(pos) {
    this.play.visible = !!pos;
    if (pos) this.play.position.set(pos[0], pos[1], pos[2]);
    this.draw();
  }

  bounds() {
    const b = new THREE.Box3();
    if (this.points) {
      for (let i = 0; i < this.points.length; i += 3)
        b.expandByPoint(new THREE.Vector3(this.points[i], this.points[i + 1], this.points[i + 2]));
    } else if (this.travel) {
      b.copy(this.travel);
    } else {
      b.set(new THREE.Vector3(0, 0, 0), new THREE.Vector3(100, 100, 50));
    }
    return b;
  }

  // top (looking down Z, X right), front (looking along +Y), side (along -X), iso.
  setView(name) {
    this.viewName = name;
    const b = this.bounds();
    const c = b.getCenter(new THREE.Vector3());
    const r = Math.max(b.getSize(new THREE.Vector3()).length() / 2, 10);
    const d = r / Math.sin((this.camera.fov * Math.PI) / 360) * 1.05;
    const dir = { top: [0, -0.0001, 1], front: [0, -1, 0], side: [1, 0, 0], iso: [1, -1, 0.8] }[name] || [1, -1, 0.8];
    const v = new THREE.Vector3(...dir).normalize().multiplyScalar(d);
    this.camera.position.copy(c).add(v);
    this.camera.near = d / 100; this.camera.far = d * 100;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(c);
    this.controls.update();
    // The tool drawn to be seen at this scale (6 mm across at a 60 mm view).
    this.tool.scale.setScalar(Math.max(r / 60, 0.25));
    window.hmiStats && (window.hmiStats.preview3dView = name);
    this.draw();
  }
}

try {
  window.preview3d = new Preview3D(document.getElementById('preview3d'));
} catch (e) {
  // No WebGL here: app.js keeps the flat XY view.
  window.preview3d = null;
  window.preview3dError = String(e);
}
window.dispatchEvent(new Event('preview3d'));
