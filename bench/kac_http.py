"""Helpers shared by the service benchmarks (cancel.py, compare.py, search.py): the release binary, and JSON
calls over loopback HTTP. Standard library only."""
import json, os, subprocess, urllib.error, urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def release_kac():
    """Builds the release binary (as docker/Dockerfile does) and returns its path."""
    subprocess.run(["cargo", "build", "--release", "--locked", "--bin", "kac"], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return os.path.join(ROOT, "target", "release", "kac")


def call(base, method, path, body=None, ctype="application/json", timeout=120):
    """One request; (status, JSON body or None). `body`: bytes as they are, anything else as JSON."""
    data = body if isinstance(body, (bytes, type(None))) else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data=data, method=method)
    if data is not None:
        req.add_header("content-type", ctype)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"null")
