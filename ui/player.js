// The 3-D figure: points (markers, joints, End Sites) and, for skeleton takes, bones; one
// frame at a time. Samples missing in a frame (gaps, NaN) are left out, with their bones.

import * as THREE from 'three';
import { OrbitControls } from '/ui/vendor/three/OrbitControls.js';

export class Player {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {{points: number, bones: [number, number][], metres: number}} shape
   *   metres: metres per stored unit.
   */
  constructor(canvas, shape) {
    this.shape = shape;
    this.canvas = canvas;
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

    const n = shape.points;
    this.pointPos = new Float32Array(n * 3);
    const pg = new THREE.BufferGeometry();
    pg.setAttribute('position', new THREE.BufferAttribute(this.pointPos, 3));
    this.points = new THREE.Points(pg, new THREE.PointsMaterial({ color: 0x1f5fbf, size: 6, sizeAttenuation: false }));
    this.points.frustumCulled = false;
    this.root.add(this.points);

    this.bonePos = new Float32Array(shape.bones.length * 6);
    const bg = new THREE.BufferGeometry();
    bg.setAttribute('position', new THREE.BufferAttribute(this.bonePos, 3));
    this.bones = new THREE.LineSegments(bg, new THREE.LineBasicMaterial({ color: 0x223344 }));
    this.bones.frustumCulled = false;
    this.root.add(this.bones);

    this.resize = new ResizeObserver(() => this.fit());
    this.resize.observe(canvas);
    this.fit();
  }

  fit() {
    const w = this.canvas.clientWidth || 640;
    const h = this.canvas.clientHeight || 360;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.draw();
  }

  /** Point the camera at a frame (`xyz`, stored units), Z-up takes turned Y-up. */
  frame(xyz) {
    const m = this.shape.metres;
    const box = new THREE.Box3();
    for (let i = 0; i + 2 < xyz.length; i += 3) {
      if (Number.isFinite(xyz[i]) && Number.isFinite(xyz[i + 1]) && Number.isFinite(xyz[i + 2])) {
        box.expandByPoint(new THREE.Vector3(xyz[i] * m, xyz[i + 1] * m, xyz[i + 2] * m));
      }
    }
    if (box.isEmpty()) return;
    const size = box.getSize(new THREE.Vector3());
    // BVH is Y-up; most marker systems are Z-up: the taller of the two is up.
    this.root.rotation.x = size.z > size.y * 1.2 ? -Math.PI / 2 : 0;
    this.root.updateMatrixWorld();
    const world = box.clone().applyMatrix4(this.root.matrixWorld);
    const c = world.getCenter(new THREE.Vector3());
    const r = Math.max(world.getSize(new THREE.Vector3()).length(), 0.5);
    this.grid.position.set(c.x, world.min.y, c.z);
    this.controls.target.copy(c);
    this.camera.position.set(c.x + r * 0.9, c.y + r * 0.35, c.z + r * 1.2);
    this.camera.near = r / 100;
    this.camera.far = r * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
  }

  /** Show one frame (`xyz`: points × 3, stored units, NaN where missing). */
  show(xyz) {
    const m = this.shape.metres;
    let k = 0;
    for (let p = 0; p < this.shape.points; p++) {
      const x = xyz[3 * p];
      const y = xyz[3 * p + 1];
      const z = xyz[3 * p + 2];
      if (Number.isFinite(x) && Number.isFinite(y) && Number.isFinite(z)) {
        this.pointPos[k++] = x * m;
        this.pointPos[k++] = y * m;
        this.pointPos[k++] = z * m;
      }
    }
    this.points.geometry.setDrawRange(0, k / 3);
    this.points.geometry.attributes.position.needsUpdate = true;
    let b = 0;
    for (const [a, c] of this.shape.bones) {
      const pa = xyz.subarray(3 * a, 3 * a + 3);
      const pc = xyz.subarray(3 * c, 3 * c + 3);
      if (pa.every(Number.isFinite) && pc.every(Number.isFinite)) {
        for (const v of pa) this.bonePos[b++] = v * m;
        for (const v of pc) this.bonePos[b++] = v * m;
      }
    }
    this.bones.geometry.setDrawRange(0, b / 3);
    this.bones.geometry.attributes.position.needsUpdate = true;
    this.draw();
  }

  draw() {
    this.renderer.render(this.scene, this.camera);
  }

  dispose() {
    this.resize.disconnect();
    this.controls.dispose();
    this.renderer.dispose();
  }
}
