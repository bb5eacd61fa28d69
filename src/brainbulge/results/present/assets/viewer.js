/* brainbulge 3D viewer: WebGL 1, no dependencies, written for brainbulge's report.html and
 * view.html (brainbulge.results.webview builds the scenes).
 *
 * A scene (JSON in <script type="application/json" id=...>, arrays base64 encoded) is a list
 * of layers: triangle meshes (reference positions X, displacement U, triangles T, per-vertex
 * values per field, or one colour) and line sets (X, U, edges E); a layer with "like": i
 * takes X and T (or E) of layer i, not its U or values. A layer shows in the modes
 * it names, is cut by the mode's clip plane when it says "clip", and shows only with the
 * "undeformed" box ticked when it is "undeformed". Every <div class="bbview" data-scene=id>
 * becomes a view when it first scrolls near the screen; window.brainbulgeViews lists them
 * ({id, frames, error, ...}) for tests. Drag: rotate; wheel: zoom; shift-drag: pan;
 * double-click: first preset view.
 */
(function () {
  "use strict";
  var views = (window.brainbulgeViews = []);

  function decode(s, Type) {
    var bin = atob(s), n = bin.length, u8 = new Uint8Array(n);
    for (var i = 0; i < n; i++) u8[i] = bin.charCodeAt(i);
    return new Type(u8.buffer);
  }

  // --- small matrix helpers (column-major 4x4) ---
  function perspective(fovy, aspect, near, far) {
    var f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  }
  function mul(a, b) {
    var o = new Array(16);
    for (var c = 0; c < 4; c++)
      for (var r = 0; r < 4; r++) {
        var s = 0;
        for (var k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
        o[c * 4 + r] = s;
      }
    return o;
  }
  function rot3(axis, ang) { // rotation matrix (rows) about a unit axis
    var c = Math.cos(ang), s = Math.sin(ang), t = 1 - c, x = axis[0], y = axis[1], z = axis[2];
    return [[t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c]];
  }
  function mul3(a, b) {
    var o = [[0, 0, 0], [0, 0, 0], [0, 0, 0]];
    for (var i = 0; i < 3; i++) for (var j = 0; j < 3; j++)
      for (var k = 0; k < 3; k++) o[i][j] += a[i][k] * b[k][j];
    return o;
  }

  var VS = [
    "attribute vec3 aX; attribute vec3 aU; attribute vec3 aN; attribute float aV;",
    "uniform mat4 uMVP; uniform mat4 uMV; uniform vec4 uClip; uniform float uWarp;",
    "varying float vV; varying vec3 vN; varying float vClip;",
    "void main() {",
    "  gl_Position = uMVP * vec4(aX + uWarp * aU, 1.0);",
    "  vN = (uMV * vec4(aN, 0.0)).xyz; vV = aV; vClip = dot(uClip.xyz, aX) - uClip.w;",
    "}"].join("\n");
  var FS = [
    "precision highp float;",
    "uniform sampler2D uCmap; uniform vec2 uRange; uniform vec3 uColor; uniform float uUseColor;",
    "uniform float uAlpha; uniform float uLit;",
    "varying float vV; varying vec3 vN; varying float vClip;",
    "void main() {",
    "  if (vClip > 0.0) discard;",
    "  vec3 base = uColor;",
    "  if (uUseColor < 0.5) {",
    "    if (vV < -1e29) base = vec3(0.55);",
    "    else base = texture2D(uCmap, vec2(clamp((vV - uRange.x) / (uRange.y - uRange.x), 0.0, 1.0), 0.5)).rgb;",
    "  }",
    "  vec3 c = base;",
    "  if (uLit > 0.5) {",
    "    vec3 n = normalize(vN);",
    "    float key = abs(dot(n, normalize(vec3(0.35, 0.45, 1.0))));",
    "    float fill = abs(dot(n, normalize(vec3(-0.6, -0.2, 0.8))));",
    "    c = base * (0.28 + 0.55 * key + 0.22 * fill) + vec3(0.18) * pow(key, 24.0);",
    "  }",
    "  gl_FragColor = vec4(c, uAlpha);",
    "}"].join("\n");

  function compile(gl, type, src) {
    var sh = gl.createShader(type);
    gl.shaderSource(sh, src);
    gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(sh));
    return sh;
  }

  function vertexNormals(P, T) {
    var N = new Float32Array(P.length);
    for (var f = 0; f < T.length; f += 3) {
      var a = 3 * T[f], b = 3 * T[f + 1], c = 3 * T[f + 2];
      var ux = P[b] - P[a], uy = P[b + 1] - P[a + 1], uz = P[b + 2] - P[a + 2];
      var vx = P[c] - P[a], vy = P[c + 1] - P[a + 1], vz = P[c + 2] - P[a + 2];
      var nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (var k = 0; k < 3; k++) {
        var i = 3 * T[f + k];
        N[i] += nx; N[i + 1] += ny; N[i + 2] += nz;
      }
    }
    return N;
  }

  function el(tag, attrs, parent, text) {
    var e = document.createElement(tag);
    for (var k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text;
    if (parent) parent.appendChild(e);
    return e;
  }

  function View(root) {
    var self = this;
    this.id = root.id || root.getAttribute("data-scene");
    this.frames = 0;
    this.error = null;
    views.push(this);
    var scene = JSON.parse(document.getElementById(root.getAttribute("data-scene")).textContent);
    this.scene = scene;
    var fieldNames = Object.keys(scene.fields);
    this.field = fieldNames[0];
    this.mode = scene.modes ? scene.modes[0][0] : null;
    this.undeformed = false;
    this.flip = false;

    // --- controls ---
    var bar = el("div", { "class": "bbbar" }, root);
    var fsel = el("select", { "class": "bbfield", "aria-label": "field" }, bar);
    fieldNames.forEach(function (f) { el("option", { value: f }, fsel, scene.fields[f].label); });
    fsel.addEventListener("change", function () { self.field = fsel.value; self.update(); });
    var msel = null;
    if (scene.modes) {
      msel = el("select", { "class": "bbmode", "aria-label": "what to show" }, bar);
      scene.modes.forEach(function (m) { el("option", { value: m[0] }, msel, m[1]); });
      msel.addEventListener("change", function () {
        self.mode = msel.value;
        scene.modes.forEach(function (m) { if (m[0] === self.mode && m[2]) self.setView(m[2], true); });
        self.update();
      });
      var lab = el("label", {}, bar);
      var und = el("input", { type: "checkbox", "class": "bbundeformed" }, lab);
      lab.appendChild(document.createTextNode(" undeformed"));
      und.addEventListener("change", function () { self.undeformed = und.checked; self.redraw(); });
      var lab2 = el("label", {}, bar);
      var flip = el("input", { type: "checkbox", "class": "bbflip" }, lab2);
      lab2.appendChild(document.createTextNode(" other half"));
      flip.addEventListener("change", function () { self.flip = flip.checked; self.redraw(); });
    }
    Object.keys(scene.views).forEach(function (name) {
      var b = el("button", { type: "button" }, bar, name);
      b.addEventListener("click", function () { self.setView(name); });
    });
    this.fsel = fsel;
    this.msel = msel;
    var canvas = el("canvas", { "class": "bbcanvas" }, root);
    this.canvas = canvas;
    var legend = el("div", { "class": "bblegend" }, root);
    this.bar = el("canvas", { width: 256, height: 14 }, legend);
    this.ticks = el("div", { "class": "bbticks" }, legend);
    this.note = el("div", { "class": "bbnote" }, legend);
    if (scene.caption) el("div", { "class": "bbcaption" }, root, scene.caption);

    var gl = canvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true });
    if (!gl) throw new Error("this browser has no WebGL: the 3D view cannot be drawn");
    this.gl = gl;
    gl.getExtension("OES_element_index_uint");
    var prog = gl.createProgram();
    gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, VS));
    gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER, FS));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
    this.prog = prog;
    this.loc = {};
    ["aX", "aU", "aN", "aV"].forEach(function (a) { self.loc[a] = gl.getAttribLocation(prog, a); });
    ["uMVP", "uMV", "uClip", "uWarp", "uCmap", "uRange", "uColor", "uUseColor", "uAlpha", "uLit"]
      .forEach(function (u) { self.loc[u] = gl.getUniformLocation(prog, u); });

    // colour maps: 256 x 1 RGB textures
    this.cmaps = {};
    this.cmapBytes = {};
    Object.keys(scene.cmaps).forEach(function (name) {
      var rgb = decode(scene.cmaps[name], Uint8Array), rgba = new Uint8Array(256 * 4);
      for (var i = 0; i < 256; i++) {
        rgba[4 * i] = rgb[3 * i]; rgba[4 * i + 1] = rgb[3 * i + 1]; rgba[4 * i + 2] = rgb[3 * i + 2];
        rgba[4 * i + 3] = 255;
      }
      var tex = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, tex);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, 256, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, rgba);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      self.cmaps[name] = tex;
      self.cmapBytes[name] = rgba;
    });

    // layers -> buffers
    this.layers = scene.layers.map(function (L) {
      var src = L.like === undefined ? L : scene.layers[L.like]; // X and T of an earlier layer
      var X = decode(src.X, Float32Array);
      var U = L.U ? decode(L.U, Float32Array) : new Float32Array(X.length);
      var lines = !!src.E;
      var idx = decode(lines ? src.E : src.T, Uint32Array);
      var P = new Float32Array(X.length);
      for (var i = 0; i < X.length; i++) P[i] = X[i] + U[i];
      var N = lines ? new Float32Array(X.length) : vertexNormals(P, idx);
      var values = {};
      Object.keys(L.values || {}).forEach(function (f) { values[f] = decode(L.values[f], Float32Array); });
      function buf(data, target) {
        var b = gl.createBuffer();
        gl.bindBuffer(target || gl.ARRAY_BUFFER, b);
        gl.bufferData(target || gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
        return b;
      }
      return {
        spec: L, lines: lines, count: idx.length, n: X.length / 3,
        X: buf(X), U: buf(U), N: buf(N), I: buf(idx, gl.ELEMENT_ARRAY_BUFFER),
        V: buf(new Float32Array(X.length / 3)), values: values
      };
    });

    // camera
    this.centre = scene.centre;
    this.radius = scene.radius;
    this.zoom = 1;
    this.pan = [0, 0];
    this.setView(Object.keys(scene.views)[0], true);
    var drag = null;
    canvas.addEventListener("pointerdown", function (e) {
      drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", function (e) {
      if (!drag) return;
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) {
        var s = 2 * self.radius / (self.zoom * canvas.clientHeight);
        self.pan[0] += dx * s; self.pan[1] -= dy * s;
      } else {
        self.R = mul3(rot3([1, 0, 0], dy * 0.01), mul3(rot3([0, 1, 0], dx * 0.01), self.R));
      }
      self.redraw();
    });
    canvas.addEventListener("pointerup", function () { drag = null; });
    canvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
    canvas.addEventListener("wheel", function (e) {
      e.preventDefault();
      self.zoom = Math.min(20, Math.max(0.2, self.zoom * Math.exp(-e.deltaY * 0.0015)));
      self.redraw();
    }, { passive: false });
    canvas.addEventListener("dblclick", function () { self.setView(Object.keys(scene.views)[0]); });
    window.addEventListener("resize", function () { self.redraw(); });
    this.update();
  }

  View.prototype.setView = function (name, quiet) {
    var v = this.scene.views[name]; // rows: right, up, view direction
    this.R = [v[0], v[1], [-v[2][0], -v[2][1], -v[2][2]]];
    this.zoom = 1;
    this.pan = [0, 0];
    if (!quiet) this.redraw();
  };

  View.prototype.update = function () { // the field or the mode changed
    var gl = this.gl, f = this.field, self = this;
    this.layers.forEach(function (L) {
      var v = L.values[f];
      if (v) {
        gl.bindBuffer(gl.ARRAY_BUFFER, L.V);
        gl.bufferData(gl.ARRAY_BUFFER, v, gl.STATIC_DRAW);
      }
    });
    var info = this.scene.fields[f], rgba = this.cmapBytes[info.cmap];
    var ctx = this.bar.getContext("2d"), img = ctx.createImageData(256, 14);
    for (var y = 0; y < 14; y++) img.data.set(rgba, y * 256 * 4);
    ctx.putImageData(img, 0, 0);
    var lo = info.range[0], hi = info.range[1];
    var fmt = function (x) { return Math.abs(x) >= 100 ? x.toFixed(0) : x.toPrecision(3); };
    this.ticks.textContent = fmt(lo) + "  \u2014  " + fmt((lo + hi) / 2) + "  \u2014  " + fmt(hi);
    this.note.textContent = info.label + (info.note ? " (" + info.note + ")" : "");
    self.redraw();
  };

  View.prototype.redraw = function () {
    var self = this;
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(function () {
      self.pending = false;
      try { self.draw(); } catch (e) { self.error = String(e); throw e; }
    });
  };

  View.prototype.draw = function () {
    var gl = this.gl, c = this.canvas, loc = this.loc, scene = this.scene, self = this;
    var dpr = window.devicePixelRatio || 1;
    var w = Math.max(1, Math.round(c.clientWidth * dpr)), h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
    gl.viewport(0, 0, w, h);
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(this.prog);
    var r = this.radius, dist = 3.2 * r / this.zoom, R = this.R, ce = this.centre;
    // model-view: rotate about the centre, then move back by dist
    var t = [0, 0, 0];
    for (var i = 0; i < 3; i++) t[i] = -(R[i][0] * ce[0] + R[i][1] * ce[1] + R[i][2] * ce[2]);
    var MV = [R[0][0], R[1][0], R[2][0], 0, R[0][1], R[1][1], R[2][1], 0, R[0][2], R[1][2], R[2][2], 0,
              t[0] + this.pan[0], t[1] + this.pan[1], t[2] - dist, 1];
    var near = Math.max(0.05 * r, dist - 2.5 * r), far = dist + 2.5 * r;
    var MVP = mul(perspective(0.55, w / h, near, far), MV);
    gl.uniformMatrix4fv(loc.uMVP, false, new Float32Array(MVP));
    gl.uniformMatrix4fv(loc.uMV, false, new Float32Array(MV));
    var info = scene.fields[this.field];
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.cmaps[info.cmap]);
    gl.uniform1i(loc.uCmap, 0);
    gl.uniform2f(loc.uRange, info.range[0], info.range[1] > info.range[0] ? info.range[1] : info.range[0] + 1e-9);
    var plane = (scene.clip && this.mode && scene.clip[this.mode]) || null;
    var sign = this.flip ? -1 : 1;
    var order = this.layers.filter(function (L) {
      var s = L.spec;
      if (s.modes && self.mode && s.modes.indexOf(self.mode) < 0) return false;
      if (s.undeformed && !self.undeformed) return false;
      return true;
    });
    order.sort(function (a, b) { return (b.spec.alpha || 1) - (a.spec.alpha || 1); }); // opaque first
    order.forEach(function (L) {
      var s = L.spec, alpha = s.alpha || 1;
      if (s.clip && plane) gl.uniform4f(loc.uClip, sign * plane[0], sign * plane[1], sign * plane[2], sign * plane[3]);
      else gl.uniform4f(loc.uClip, 0, 0, 0, 1);
      gl.uniform1f(loc.uWarp, s.undeformed ? 0 : 1);
      var useColor = !L.values[self.field];
      gl.uniform1f(loc.uUseColor, useColor ? 1 : 0);
      var col = s.color || [0.6, 0.6, 0.6];
      gl.uniform3f(loc.uColor, col[0], col[1], col[2]);
      gl.uniform1f(loc.uAlpha, alpha);
      gl.uniform1f(loc.uLit, L.lines ? 0 : 1);
      if (alpha < 1) {
        gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA); gl.depthMask(false);
      } else {
        gl.disable(gl.BLEND); gl.depthMask(true);
      }
      [["aX", L.X, 3], ["aU", L.U, 3], ["aN", L.N, 3], ["aV", L.V, 1]].forEach(function (a) {
        gl.bindBuffer(gl.ARRAY_BUFFER, a[1]);
        gl.enableVertexAttribArray(loc[a[0]]);
        gl.vertexAttribPointer(loc[a[0]], a[2], gl.FLOAT, false, 0, 0);
      });
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, L.I);
      gl.drawElements(L.lines ? gl.LINES : gl.TRIANGLES, L.count, gl.UNSIGNED_INT, 0);
    });
    gl.depthMask(true);
    this.frames += 1;
  };

  View.prototype.setField = function (f) { this.fsel.value = f; this.fsel.dispatchEvent(new Event("change")); };

  function start(root) {
    if (root.getAttribute("data-started")) return;
    root.setAttribute("data-started", "1");
    try { new View(root); } catch (e) {
      el("div", { "class": "bberror" }, root, "3D view failed: " + e.message);
      views.push({ id: root.getAttribute("data-scene"), frames: 0, error: String(e) });
      throw e;
    }
  }
  var roots = Array.prototype.slice.call(document.querySelectorAll(".bbview"));
  if ("IntersectionObserver" in window) {
    var io = new IntersectionObserver(function (entries) {
      entries.forEach(function (e) { if (e.isIntersecting) { io.unobserve(e.target); start(e.target); } });
    }, { rootMargin: "300px" });
    roots.forEach(function (r) { io.observe(r); });
  } else {
    roots.forEach(start);
  }
  window.brainbulgeStartAll = function () { roots.forEach(start); };
})();
