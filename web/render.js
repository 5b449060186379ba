// WebGL2 view of a shape coloured by one scalar per vertex: triangles (lit from the camera, both sides), or
// points for point clouds, segments for curves and graphs. The scalar is mapped to a viridis-like ramp in the
// fragment shader over [lo, hi], with optional isolines; NaN (a vertex without a value) is grey. Orbit with the
// left button, pan with the right (or shift), zoom with the wheel. Picking: the vertex nearest the ray through the
// clicked pixel, among the front-most triangle's corners (triangles) or the points near the ray.

const VERT = `#version 300 es
in vec3 position;
in float value;
uniform mat4 view, proj;
uniform float pointSize;
out float v;
out vec3 eyePos;
void main() {
  vec4 p = view * vec4(position, 1.0);
  eyePos = p.xyz;
  v = value;
  gl_Position = proj * p;
  gl_PointSize = pointSize;
}`;

const FRAG = `#version 300 es
precision highp float;
in float v;
in vec3 eyePos;
uniform float lo, hi, isolines, lit;
uniform vec3 picked;
out vec4 colour;
vec3 ramp(float t) {
  // dark blue → teal → yellow (the ramp of kac's coloured PLY export)
  vec3 a = vec3(0.267, 0.005, 0.329), b = vec3(0.128, 0.567, 0.551), c = vec3(0.993, 0.906, 0.144);
  return t < 0.5 ? mix(a, b, t * 2.0) : mix(b, c, t * 2.0 - 1.0);
}
void main() {
  vec3 base;
  if (isnan(v) || isinf(v)) {
    base = vec3(0.55);
  } else {
    float t = clamp((v - lo) / max(hi - lo, 1e-30), 0.0, 1.0);
    base = ramp(t);
    if (isolines > 0.0) {
      float s = t * isolines;
      float w = fwidth(s);
      float line = 1.0 - smoothstep(0.0, 1.5 * w, abs(fract(s - 0.5) - 0.5));
      base = mix(base, vec3(0.05), 0.8 * line);
    }
  }
  float shade = 1.0;
  if (lit > 0.5) {
    vec3 n = normalize(cross(dFdx(eyePos), dFdy(eyePos)));
    shade = 0.35 + 0.65 * abs(n.z);
  }
  colour = vec4(base * shade, 1.0);
}`;

function mat4Perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
}

// The camera looks at `target` from `distance` along the direction given by yaw and pitch.
function mat4View(cam) {
  const cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw), cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
  const dir = [cp * sy, sp, cp * cy];
  const eye = cam.target.map((t, i) => t + cam.distance * dir[i]);
  const z = dir;
  let x = [z[2], 0, -z[0]];
  const xl = Math.hypot(...x) || 1;
  x = x.map((c) => c / xl);
  const y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  return {
    m: new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]),
    eye, x, y, z,
  };
}

export class Viewer {
  constructor(canvas) {
    this.canvas = canvas;
    const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
    if (!gl) throw new Error('WebGL2 is not available in this browser');
    this.gl = gl;
    this.program = this.compile(VERT, FRAG);
    this.range = [0, 1];
    this.isolines = 0;
    this.frames = 0;
    this.onpick = null;
    this.cam = { yaw: 0.6, pitch: 0.35, distance: 3, target: [0, 0, 0] };
    this.bindInput();
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  compile(vs, fs) {
    const gl = this.gl;
    const shader = (type, src) => {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    };
    const p = gl.createProgram();
    gl.attachShader(p, shader(gl.VERTEX_SHADER, vs));
    gl.attachShader(p, shader(gl.FRAGMENT_SHADER, fs));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }

  // geometry: { positions: Float32Array (3n), triangles: Uint32Array, segments: Uint32Array }
  setGeometry(geometry) {
    const gl = this.gl;
    this.geometry = geometry;
    const n = geometry.positions.length / 3;
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    const pos = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, pos);
    gl.bufferData(gl.ARRAY_BUFFER, geometry.positions, gl.STATIC_DRAW);
    const loc = gl.getAttribLocation(this.program, 'position');
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
    this.valueBuffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, this.valueBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(n).fill(0.5), gl.DYNAMIC_DRAW);
    const vloc = gl.getAttribLocation(this.program, 'value');
    gl.enableVertexAttribArray(vloc);
    gl.vertexAttribPointer(vloc, 1, gl.FLOAT, false, 0, 0);
    this.index = null;
    this.mode = gl.POINTS;
    this.count = n;
    const indices = geometry.triangles.length ? geometry.triangles : geometry.segments;
    if (indices.length) {
      this.index = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.index);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
      this.mode = geometry.triangles.length ? gl.TRIANGLES : gl.LINES;
      this.count = indices.length;
    }
    gl.bindVertexArray(null);
    // Frame the shape.
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < n; i++) {
      for (let c = 0; c < 3; c++) {
        const x = geometry.positions[3 * i + c];
        if (x < lo[c]) lo[c] = x;
        if (x > hi[c]) hi[c] = x;
      }
    }
    this.radius = Math.max(1e-9, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
    this.cam.target = lo.map((l, c) => 0.5 * (l + hi[c]));
    this.cam.distance = 2.6 * this.radius;
    this.values = null;
    this.marker = null;
    this.firstColouredAt = 0;
    this.draw();
  }

  // values: one number per vertex of the geometry (NaN where there is none); range [lo, hi].
  setValues(values, lo, hi) {
    const gl = this.gl;
    this.values = values;
    this.range = [lo, hi];
    gl.bindBuffer(gl.ARRAY_BUFFER, this.valueBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, values instanceof Float32Array ? values : new Float32Array(values), gl.DYNAMIC_DRAW);
    this.draw();
  }

  draw() {
    if (this.pending) return;
    this.pending = requestAnimationFrame(() => {
      this.pending = 0;
      this.render();
    });
  }

  render() {
    const gl = this.gl, c = this.canvas;
    const w = Math.max(1, Math.round(c.clientWidth * devicePixelRatio)), h = Math.max(1, Math.round(c.clientHeight * devicePixelRatio));
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    gl.viewport(0, 0, w, h);
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!this.vao) return;
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(this.program);
    // A canvas taller than wide (two shapes side by side) steps back so that the shape fits across it too.
    const cam = { ...this.cam, distance: this.cam.distance * Math.max(1, h / w) };
    const view = mat4View(cam);
    this.viewMatrix = view;
    const near = Math.max(cam.distance - 2 * this.radius, this.radius * 1e-3);
    const proj = mat4Perspective(0.7, w / h, near, cam.distance + 2 * this.radius);
    this.projMatrix = proj;
    const u = (name) => gl.getUniformLocation(this.program, name);
    gl.uniformMatrix4fv(u('view'), false, view.m);
    gl.uniformMatrix4fv(u('proj'), false, proj);
    gl.uniform1f(u('lo'), this.range[0]);
    gl.uniform1f(u('hi'), this.range[1]);
    gl.uniform1f(u('isolines'), this.isolines);
    gl.uniform1f(u('lit'), this.mode === gl.TRIANGLES ? 1 : 0);
    gl.uniform1f(u('pointSize'), Math.max(2, 3 * devicePixelRatio));
    gl.bindVertexArray(this.vao);
    if (this.index) gl.drawElements(this.mode, this.count, gl.UNSIGNED_INT, 0);
    else gl.drawArrays(gl.POINTS, 0, this.count);
    gl.bindVertexArray(null);
    this.drawMarker(view.m, proj);
    this.frames++;
    if (this.values && !this.firstColouredAt) this.firstColouredAt = performance.now();
  }

  // The picked vertex as a red dot on top of the shape.
  setMarker(v) {
    this.marker = v;
    this.draw();
  }

  drawMarker(view, proj) {
    if (this.marker === null || this.marker === undefined || !this.geometry) return;
    const gl = this.gl;
    if (!this.markerProgram) {
      this.markerProgram = this.compile(
        `#version 300 es
        in vec3 position; uniform mat4 view, proj; uniform float size;
        void main() { gl_Position = proj * view * vec4(position, 1.0); gl_Position.z -= 0.002 * gl_Position.w; gl_PointSize = size; }`,
        `#version 300 es
        precision highp float; out vec4 colour;
        void main() { if (length(gl_PointCoord - 0.5) > 0.5) discard; colour = vec4(0.85, 0.1, 0.1, 1.0); }`,
      );
      this.markerBuffer = gl.createBuffer();
      this.markerVao = gl.createVertexArray();
    }
    const P = this.geometry.positions, i = this.marker;
    gl.useProgram(this.markerProgram);
    gl.bindVertexArray(this.markerVao);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.markerBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([P[3 * i], P[3 * i + 1], P[3 * i + 2]]), gl.DYNAMIC_DRAW);
    const loc = gl.getAttribLocation(this.markerProgram, 'position');
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
    gl.uniformMatrix4fv(gl.getUniformLocation(this.markerProgram, 'view'), false, view);
    gl.uniformMatrix4fv(gl.getUniformLocation(this.markerProgram, 'proj'), false, proj);
    gl.uniform1f(gl.getUniformLocation(this.markerProgram, 'size'), 9 * devicePixelRatio);
    gl.drawArrays(gl.POINTS, 0, 1);
    gl.bindVertexArray(null);
  }

  bindInput() {
    const c = this.canvas;
    let drag = null;
    c.addEventListener('contextmenu', (e) => e.preventDefault());
    c.addEventListener('pointerdown', (e) => {
      drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey, moved: false };
      c.setPointerCapture(e.pointerId);
    });
    c.addEventListener('pointermove', (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
      drag.x = e.clientX;
      drag.y = e.clientY;
      if (drag.pan) {
        const v = this.viewMatrix, s = (2 * this.cam.distance * Math.tan(0.35)) / c.clientHeight;
        this.cam.target = this.cam.target.map((t, i) => t - s * (dx * v.x[i] - dy * v.y[i]));
      } else {
        this.cam.yaw -= dx * 0.01;
        this.cam.pitch = Math.max(-1.55, Math.min(1.55, this.cam.pitch + dy * 0.01));
      }
      this.draw();
    });
    c.addEventListener('pointerup', (e) => {
      if (drag && !drag.moved && this.onpick) {
        const r = c.getBoundingClientRect();
        const v = this.pick(e.clientX - r.left, e.clientY - r.top);
        if (v !== null) this.onpick(v);
      }
      drag = null;
    });
    c.addEventListener('wheel', (e) => {
      e.preventDefault();
      this.cam.distance *= Math.exp(e.deltaY * 0.001);
      this.draw();
    }, { passive: false });
  }

  // The ray through pixel (px, py) in world space.
  ray(px, py) {
    const c = this.canvas, v = this.viewMatrix;
    const t = Math.tan(0.35), aspect = c.clientWidth / c.clientHeight;
    const sx = ((2 * px) / c.clientWidth - 1) * t * aspect, sy = (1 - (2 * py) / c.clientHeight) * t;
    const d = [0, 1, 2].map((i) => sx * v.x[i] + sy * v.y[i] - v.z[i]);
    const l = Math.hypot(...d);
    return { o: v.eye, d: d.map((x) => x / l) };
  }

  // The picked vertex (index into the geometry), or null.
  pick(px, py) {
    const g = this.geometry;
    if (!g) return null;
    const { o, d } = this.ray(px, py);
    const P = g.positions, T = g.triangles;
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const at = (i) => [P[3 * i], P[3 * i + 1], P[3 * i + 2]];
    if (T.length) {
      let best = Infinity, hit = null;
      for (let f = 0; f < T.length; f += 3) {
        const a = at(T[f]), b = at(T[f + 1]), cc = at(T[f + 2]);
        const e1 = sub(b, a), e2 = sub(cc, a), p = cross(d, e2), det = dot(e1, p);
        if (Math.abs(det) < 1e-20) continue;
        const s = sub(o, a), u = dot(s, p) / det;
        if (u < 0 || u > 1) continue;
        const q = cross(s, e1), w = dot(d, q) / det;
        if (w < 0 || u + w > 1) continue;
        const t = dot(e2, q) / det;
        if (t > 0 && t < best) {
          best = t;
          hit = [f, u, w];
        }
      }
      if (!hit) return null;
      const [f, u, w] = hit;
      const bary = [1 - u - w, u, w];
      return T[f + bary.indexOf(Math.max(...bary))];
    }
    // Points and curves: the vertex nearest the ray, within a few pixels' worth.
    let best = Infinity, which = null;
    const tol = (this.radius * 0.03) ** 2;
    for (let i = 0; i < P.length / 3; i++) {
      const s = sub(at(i), o), t = dot(s, d);
      if (t <= 0) continue;
      const d2 = dot(s, s) - t * t;
      if (d2 < tol && t < best) {
        best = t;
        which = i;
      }
    }
    return which;
  }
}

// The ramp as CSS colours (for the colour bar), matching the shader.
export function rampCss(t) {
  const a = [0.267, 0.005, 0.329], b = [0.128, 0.567, 0.551], c = [0.993, 0.906, 0.144];
  const m = t < 0.5 ? a.map((x, i) => x + (b[i] - x) * t * 2) : b.map((x, i) => x + (c[i] - x) * (t * 2 - 1));
  return `rgb(${m.map((x) => Math.round(255 * x)).join(',')})`;
}
