// The 3-D view: one scene, camera and orbit control per canvas, holding one figure per take
// shown (several overlaid on the compare page). A figure is points (markers, joints, End
// Sites) and, for skeleton takes, bones; samples missing in a frame (gaps, NaN) are left
// out, with their bones.

import * as THREE from '/ui/vendor/three/three.module.js';
import { OrbitControls } from '/ui/vendor/three/OrbitControls.js';
import { GLTFLoader } from '/ui/vendor/three/GLTFLoader.js';

/** Figure colours, in order; the first is the single-take colour. */
export const COLOURS = ['#1f5fbf', '#c0392b', '#1e8449', '#8e44ad', '#d35400', '#117a8b'];

const finite = (x, y, z) => Number.isFinite(x) && Number.isFinite(y) && Number.isFinite(z);

/** A signed axis as the API writes it (`y`, `-z`) as a unit vector; null for none. */
function axisVector(axis) {
  const m = /^([+-]?)([xyz])$/.exec(axis ?? '');
  if (!m) return null;
  const v = new THREE.Vector3();
  v.setComponent('xyz'.indexOf(m[2]), m[1] === '-' ? -1 : 1);
  return v;
}

class Figure {
  constructor(player, shape, colour) {
    this.player = player;
    this.shape = shape;
    this.group = new THREE.Group();
    player.root.add(this.group);

    const n = shape.points;
    this.pointPos = new Float32Array(n * 3);
    const pg = new THREE.BufferGeometry();
    pg.setAttribute('position', new THREE.BufferAttribute(this.pointPos, 3));
    pg.setDrawRange(0, 0);
    this.points = new THREE.Points(pg, new THREE.PointsMaterial({ color: colour, size: 6, sizeAttenuation: false }));
    this.points.frustumCulled = false;
    this.group.add(this.points);

    this.bonePos = new Float32Array(shape.bones.length * 6);
    const bg = new THREE.BufferGeometry();
    bg.setAttribute('position', new THREE.BufferAttribute(this.bonePos, 3));
    bg.setDrawRange(0, 0);
    // Bones darker than their points, so a figure's joints stay visible.
    const bone = new THREE.Color(colour).multiplyScalar(0.55);
    this.bones = new THREE.LineSegments(bg, new THREE.LineBasicMaterial({ color: bone }));
    this.bones.frustumCulled = false;
    this.group.add(this.bones);
  }

  /**
   * Turn the take's up (its body's, as the server derived or was told it) onto the view's
   * +Y. A take whose up nothing told is shown as stored: never a guess from its extent.
   */
  orient() {
    const up = axisVector(this.shape.up);
    if (up) this.group.quaternion.setFromUnitVectors(up, new THREE.Vector3(0, 1, 0));
    this.group.updateMatrixWorld();
  }

  /** The world position (metres) of the centroid of points `set` in the frame set, or null. */
  centroid(set) {
    const xyz = this.xyz;
    if (!xyz || !set?.length) return null;
    const m = this.shape.metres;
    const sum = new THREE.Vector3();
    let k = 0;
    for (const p of set) {
      const [x, y, z] = [xyz[3 * p], xyz[3 * p + 1], xyz[3 * p + 2]];
      if (finite(x, y, z)) {
        sum.add(new THREE.Vector3(x * m, y * m, z * m));
        k += 1;
      }
    }
    return k ? sum.divideScalar(k).applyMatrix4(this.group.matrixWorld) : null;
  }

  localBox(xyz) {
    const m = this.shape.metres;
    const box = new THREE.Box3();
    const v = new THREE.Vector3();
    for (let i = 0; i + 2 < xyz.length; i += 3) {
      if (finite(xyz[i], xyz[i + 1], xyz[i + 2])) box.expandByPoint(v.set(xyz[i] * m, xyz[i + 1] * m, xyz[i + 2] * m));
    }
    return box;
  }

  /**
   * Name the points on screen: one label per point in `box` (an element laid over the
   * canvas), placed at every draw; `null` removes them.
   */
  label(names, box) {
    this.labelBox?.replaceChildren();
    this.labelBox = box;
    this.labels = names ? names.map((n) => {
      const e = document.createElement('span');
      e.textContent = n;
      box.append(e);
      return e;
    }) : null;
    this.player.draw();
  }

  /** Move the labels to their points as the camera sees them now; missing points' are hidden. */
  placeLabels(camera, width, height) {
    if (!this.labels || !this.xyz) return;
    const m = this.shape.metres;
    const v = new THREE.Vector3();
    this.labels.forEach((e, p) => {
      const [x, y, z] = [this.xyz[3 * p], this.xyz[3 * p + 1], this.xyz[3 * p + 2]];
      if (!finite(x, y, z)) {
        e.hidden = true;
        return;
      }
      v.set(x * m, y * m, z * m).applyMatrix4(this.group.matrixWorld).project(camera);
      e.hidden = v.z > 1 || Math.abs(v.x) > 1 || Math.abs(v.y) > 1;
      e.style.transform = `translate(${((v.x + 1) / 2) * width + 5}px, ${((1 - v.y) / 2) * height - 8}px)`;
    });
  }

  /** Set one frame (`xyz`: points × 3, stored units, NaN where missing); not yet drawn. */
  set(xyz) {
    this.xyz = xyz;
    const m = this.shape.metres;
    let k = 0;
    for (let p = 0; p < this.shape.points; p++) {
      const x = xyz[3 * p];
      const y = xyz[3 * p + 1];
      const z = xyz[3 * p + 2];
      if (finite(x, y, z)) {
        this.pointPos[k++] = x * m;
        this.pointPos[k++] = y * m;
        this.pointPos[k++] = z * m;
      }
    }
    this.points.geometry.setDrawRange(0, k / 3);
    this.points.geometry.attributes.position.needsUpdate = true;
    let b = 0;
    for (const [a, c] of this.shape.bones) {
      if (finite(xyz[3 * a], xyz[3 * a + 1], xyz[3 * a + 2]) && finite(xyz[3 * c], xyz[3 * c + 1], xyz[3 * c + 2])) {
        for (let i = 0; i < 3; i++) this.bonePos[b++] = xyz[3 * a + i] * m;
        for (let i = 0; i < 3; i++) this.bonePos[b++] = xyz[3 * c + i] * m;
      }
    }
    this.bones.geometry.setDrawRange(0, b / 3);
    this.bones.geometry.attributes.position.needsUpdate = true;
  }

  /** Set one frame and draw (the camera following the pelvis, when asked to). */
  show(xyz) {
    this.set(xyz);
    if (this.player.following === this) this.player.follow(this.centroid(this.shape.pelvis));
    this.player.draw();
  }
}

/**
 * A glTF the server wrote, played as three.js's GLTFLoader reads it (what Blender and
 * game engines will see): each node shows the file's gizmo mesh (or, for a character
 * the take was put on, the character's skinned meshes), its animation driven to the
 * player's time. Set beside the native figure, `offset` metres to the camera's right (along
 * the floor), so that both stand as far from the camera.
 */
export class GltfFigure {
  /** Parsed from `bytes` (a GLB); resolves once loaded. */
  static async load(player, bytes, offset) {
    const gltf = await new GLTFLoader().parseAsync(bytes, '');
    return new GltfFigure(player, gltf, offset);
  }

  constructor(player, gltf, offset) {
    this.player = player;
    this.gltf = gltf;
    this.group = new THREE.Group();
    player.camera.updateMatrixWorld();
    const right = new THREE.Vector3().setFromMatrixColumn(player.camera.matrixWorld, 0);
    right.y = 0;
    if (right.lengthSq() < 1e-9) right.set(1, 0, 0);
    this.group.position.copy(right.normalize().multiplyScalar(offset));
    this.group.add(gltf.scene);
    // Each node shows the file's own gizmo mesh, lit by a light of the page's.
    this.group.add(new THREE.HemisphereLight(0xffffff, 0x666666, 3));
    this.mixer = new THREE.AnimationMixer(gltf.scene);
    for (const clip of gltf.animations) this.mixer.clipAction(clip).play();
    player.scene.add(this.group);
  }

  /** Show the animation at `t` seconds from its start. */
  at(t) {
    this.mixer.setTime(Math.max(0, t));
    this.player.draw();
  }

  /** World position (metres) of the node named `name` now, or null. */
  position(name) {
    // The loader names objects after their nodes, as animation bindings spell them.
    const n = this.gltf.scene.getObjectByName(THREE.PropertyBinding.sanitizeNodeName(name));
    if (!n) return null;
    this.group.updateMatrixWorld(true);
    const v = new THREE.Vector3().setFromMatrixPosition(n.matrixWorld).sub(this.group.position);
    return [v.x, v.y, v.z];
  }

  dispose() {
    this.player.scene.remove(this.group);
  }
}

export class Player {
  /** @param {HTMLCanvasElement} canvas */
  constructor(canvas) {
    this.canvas = canvas;
    this.figures = [];
    // preserveDrawingBuffer: what is drawn can be read back (screenshots, tests).
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf4f5f7);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 1000);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => this.draw());
    this.root = new THREE.Group();
    this.scene.add(this.root);
    this.grid = new THREE.GridHelper(10, 20, 0x9aa3ad, 0xd5d9de);
    this.scene.add(this.grid);
    /** The figure whose pelvis the camera keeps in view as it moves, or null. */
    this.following = null;
    this.resize = new ResizeObserver(() => this.fit());
    this.resize.observe(canvas);
    this.fit();
  }

  /**
   * A figure of a take's shape.
   * @param {{points: number, bones: [number, number][], metres: number}} shape
   *   metres: metres per stored unit.
   */
  add(shape, colour = COLOURS[this.figures.length % COLOURS.length]) {
    const f = new Figure(this, shape, colour);
    this.figures.push(f);
    return f;
  }

  fit() {
    const w = this.canvas.clientWidth || 640;
    const h = this.canvas.clientHeight || 360;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.draw();
  }

  /**
   * Point the camera at figures' frames: `[figure, xyz]` pairs, each turned up first. False
   * (and the camera left alone) when no point of them is present.
   */
  frame(pairs) {
    const world = new THREE.Box3();
    let floor = null;
    for (const [fig, xyz] of pairs) {
      fig.orient();
      const b = fig.localBox(xyz);
      if (!b.isEmpty()) world.union(b.applyMatrix4(fig.group.matrixWorld));
      // The body's floor, along its up: after the turn, a height along +Y.
      if (fig.shape.up && fig.shape.floor !== null) floor = Math.min(floor ?? Infinity, fig.shape.floor);
    }
    if (world.isEmpty()) return false;
    const c = world.getCenter(new THREE.Vector3());
    const r = Math.max(world.getSize(new THREE.Vector3()).length(), 0.5);
    this.grid.position.set(c.x, floor ?? world.min.y, c.z);
    this.controls.target.copy(c);
    this.camera.position.set(c.x + r * 0.9, c.y + r * 0.35, c.z + r * 1.2);
    this.camera.near = r / 100;
    this.camera.far = r * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    return true;
  }

  /**
   * Keep `figure`'s pelvis in view as it moves (the camera and its target carried along
   * the floor by as much as the pelvis moved), or stop (`null`).
   */
  followFigure(figure) {
    this.following = figure;
    this.followed = null;
  }

  /** Carry the camera along the floor with `at` (the followed pelvis, world metres). */
  follow(at) {
    if (!at) return;
    if (this.followed) {
      const d = at.clone().sub(this.followed);
      d.y = 0;
      this.camera.position.add(d);
      this.controls.target.add(d);
      // The grid moves in whole cells, so the floor stays still under a walking figure.
      this.grid.position.x = Math.round(this.controls.target.x / 0.5) * 0.5;
      this.grid.position.z = Math.round(this.controls.target.z / 0.5) * 0.5;
      this.controls.update();
    }
    this.followed = at;
  }

  draw() {
    this.renderer.render(this.scene, this.camera);
    const [w, h] = [this.canvas.clientWidth, this.canvas.clientHeight];
    for (const f of this.figures) f.placeLabels(this.camera, w, h);
  }

  dispose() {
    this.resize.disconnect();
    this.controls.dispose();
    this.renderer.dispose();
  }
}
