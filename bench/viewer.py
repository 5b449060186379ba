#!/usr/bin/env python3
"""The viewer on a real size (issue 18, item 3): a 163,842-vertex icosphere with 20 eigenvectors, opened in
Debian's headless chromium (software WebGL: SwiftShader on the CPU, so these are lower bounds of what a machine
with a GPU does) through chromedriver's WebDriver API. Measures, inside the page: the time from navigation to
the first frame of the shape coloured by an eigenfunction (page load, OpenAPI document, shape summary, geometry
and the .npy of the eigenvectors fetched and drawn), frames per second while orbiting (each frame rendered and
drawn: a one-pixel read waits for it), and the time to recolour by another eigenfunction (the column mapped to the vertices, the
buffer uploaded, the frame finished). Prints one JSON line. Standard library only.

Usage: python3 bench/viewer.py [--level 7]
"""
import argparse, json, os, socket, subprocess, sys, tempfile, time, urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import call, release_kac  # noqa: E402


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def wd(base, method, path, body=None):
    req = urllib.request.Request(base + path, data=None if body is None else json.dumps(body).encode(), method=method,
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=300) as r:
        return json.loads(r.read())["value"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--level", type=int, default=7)
    a = ap.parse_args()
    kac = release_kac()
    work = tempfile.mkdtemp()
    mesh = os.path.join(work, "sphere.off")
    subprocess.run([kac, "generate", "icosphere", "--level", str(a.level), "--out", mesh], check=True,
                   stdout=subprocess.DEVNULL)
    env = dict(os.environ, KAC_ADDR="127.0.0.1:0", KAC_DATA_DIR=os.path.join(work, "data"), RUST_LOG="error",
               KAC_MAX_WAIT_S="600")
    server = subprocess.Popen([kac, "serve"], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    port = free_port()
    driver = subprocess.Popen(["chromedriver", "--port=%d" % port], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        base = "http://" + json.loads(server.stdout.readline())["listening"]
        _, shape = call(base, "POST", "/v1/shapes?format=off", open(mesh, "rb").read(), "application/octet-stream")
        st, job = call(base, "POST", "/v1/jobs", {"shape_id": shape["id"], "analysis": "spectrum", "k": 20,
                                                  "eigenvectors": True})
        while call(base, "GET", "/v1/jobs/" + job["id"])[1]["status"] != "succeeded":
            time.sleep(0.2)
        w = "http://127.0.0.1:%d" % port
        for _ in range(100):
            try:
                urllib.request.urlopen(w + "/status", timeout=1)
                break
            except Exception:
                time.sleep(0.1)
        sid = wd(w, "POST", "/session", {"capabilities": {"alwaysMatch": {"goog:chromeOptions": {
            "binary": "/usr/bin/chromium",
            "args": ["--headless=new", "--no-sandbox", "--window-size=1400,900", "--use-angle=swiftshader",
                     "--enable-unsafe-swiftshader", "--disable-dev-shm-usage"]}}}})["sessionId"]
        run = lambda script: wd(w, "POST", "/session/%s/execute/sync" % sid, {"script": script, "args": []})
        try:
            wd(w, "POST", "/session/%s/url" % sid,
               {"url": "%s/#shape=%s&job=%s&array=eigenvectors&column=1" % (base, shape["id"], job["id"])})
            t = time.time()
            while not run("return !!(window.kac && window.kac.viewer.firstColouredAt)"):
                if time.time() - t > 300:
                    raise SystemExit("the page did not draw: %s" % run("return window.kac && window.kac.errors"))
                time.sleep(0.05)
            first = run("return window.kac.viewer.firstColouredAt")
            fps = run("""
                const v = window.kac.viewer, gl = v.gl, n = 30, px = new Uint8Array(4);
                // A one-pixel read after each frame waits for it to be drawn (gl.finish does not, in Chromium).
                const sync = () => gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
                v.render(); sync();
                const t = performance.now();
                for (let i = 0; i < n; i++) { v.cam.yaw += 0.05; v.render(); sync(); }
                return n / ((performance.now() - t) / 1000);""")
            recolour = run("""
                const v = window.kac.viewer, gl = v.gl, s = document.getElementById('column'), ms = [];
                const px = new Uint8Array(4);
                for (let c = 2; c < 12; c++) {
                  const t = performance.now();
                  s.value = String(c); s.dispatchEvent(new Event('input'));
                  v.render(); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
                  ms.push(performance.now() - t);
                }
                ms.sort((a, b) => a - b);
                return ms[Math.floor(ms.length / 2)];""")
            errors = run("return window.kac.errors")
        finally:
            wd(w, "DELETE", "/session/%s" % sid)
        print(json.dumps({"vertices": shape["summary"]["vertices"],
                          "renderer": "chromium headless, SwiftShader (CPU)",
                          "first_coloured_frame_ms": round(first), "orbit_fps": round(fps, 1),
                          "recolour_ms_median": round(recolour, 1), "page_errors": errors}))
    finally:
        driver.terminate()
        server.terminate()


if __name__ == "__main__":
    main()
