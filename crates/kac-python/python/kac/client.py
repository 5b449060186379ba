"""``kac.Client``: a kac service over HTTP, with results as NumPy arrays.

The same requests as the library functions, sent to ``kac serve`` (the routes of ``openapi/openapi.json``): upload
shapes (one, or many in one bulk request), submit analyses as jobs and wait for them with progress, read results
with their arrays as NumPy (from the ``.npy`` links), search stored fingerprints, compare, and correspond. Problems
(RFC 9457) are raised as :class:`kac.KacError` with the problem's ``code``, ``status`` and members. Only the
standard library and NumPy are used.
"""

from __future__ import annotations

import io
import json
import os
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from typing import Any, Callable, Iterable, Optional

import numpy as np

from . import _kac

TERMINAL = ("succeeded", "failed", "canceled")


def _problem(status: int, body: bytes, what: str) -> Exception:
    try:
        p = json.loads(body)
    except ValueError:
        p = {"code": "internal-error", "detail": body[:200].decode("utf-8", "replace")}
    code = p.get("code", "internal-error")
    detail = p.get("detail", "")
    e = _kac.KacError(f"{code}: {detail} ({what}: HTTP {status})")
    e.code = code  # type: ignore[attr-defined]
    e.detail = detail  # type: ignore[attr-defined]
    e.status = status  # type: ignore[attr-defined]
    e.extra = p  # type: ignore[attr-defined]
    return e


class Client:
    """A kac service at ``url`` (``http://127.0.0.1:8080``), with an API key when the service asks for one."""

    def __init__(self, url: str, api_key: Optional[str] = None, timeout: float = 120.0) -> None:
        self.url = url.rstrip("/")
        self.api_key = api_key
        self.timeout = timeout

    # -- plumbing --------------------------------------------------------------------------------------------

    def _request(
        self,
        method: str,
        path: str,
        body: Optional[bytes] = None,
        content_type: Optional[str] = None,
        query: Optional[dict] = None,
    ) -> tuple:
        url = self.url + path
        if query:
            url += "?" + urllib.parse.urlencode({k: v for k, v in query.items() if v is not None})
        req = urllib.request.Request(url, data=body, method=method)
        if content_type:
            req.add_header("Content-Type", content_type)
        if self.api_key:
            req.add_header("Authorization", f"Bearer {self.api_key}")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as r:
                return r.status, r.read(), r.headers
        except urllib.error.HTTPError as e:
            raise _problem(e.code, e.read(), f"{method} {path}") from None

    def _json(self, method: str, path: str, payload: Any = None, query: Optional[dict] = None) -> Any:
        body = None if payload is None else json.dumps(payload).encode()
        _, data, _ = self._request(method, path, body, "application/json" if body is not None else None, query)
        return json.loads(data) if data else None

    @staticmethod
    def _multipart(files: Iterable[tuple], fields: Optional[dict] = None) -> tuple:
        boundary = uuid.uuid4().hex
        out = io.BytesIO()
        for name, value in (fields or {}).items():
            out.write(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n'.encode())
            out.write(b"Content-Type: application/json\r\n\r\n" + json.dumps(value).encode() + b"\r\n")
        for part, filename, data in files:
            out.write(
                f'--{boundary}\r\nContent-Disposition: form-data; name="{part}"; filename="{filename}"\r\n'.encode()
            )
            out.write(b"Content-Type: application/octet-stream\r\n\r\n" + data + b"\r\n")
        out.write(f"--{boundary}--\r\n".encode())
        return out.getvalue(), f"multipart/form-data; boundary={boundary}"

    # -- shapes ----------------------------------------------------------------------------------------------

    def upload(self, path: str, format: Optional[str] = None, tags: Optional[list] = None) -> dict:
        """Uploads one shape file; the stored shape (``id``, ``summary``, …)."""
        with open(path, "rb") as f:
            data = f.read()
        query = {"format": format, "tags": ",".join(tags) if tags else None}
        _, body, _ = self._request("POST", "/v1/shapes", data, "application/octet-stream", query)
        return json.loads(body)

    def upload_bulk(self, paths: Iterable[str], options: Optional[dict] = None) -> dict:
        """Uploads many shape files (or .zip archives) in one request; every file with its shape, its fingerprint
        job, or its problem."""
        files = []
        for p in paths:
            with open(p, "rb") as f:
                files.append(("file", os.path.basename(p), f.read()))
        body, ctype = self._multipart(files, {"options": options} if options else None)
        _, data, _ = self._request("POST", "/v1/shapes/bulk", body, ctype)
        return json.loads(data)

    def shape(self, shape_id: str) -> dict:
        return self._json("GET", f"/v1/shapes/{shape_id}")

    # -- jobs ------------------------------------------------------------------------------------------------

    def submit(self, shape_id: str, analysis: str, **request: Any) -> dict:
        """Submits an analysis of a stored shape as a job (its options as the service's JSON names them)."""
        return self._json("POST", "/v1/jobs", {"shape_id": shape_id, "analysis": analysis, **request})

    def job(self, job_id: str) -> dict:
        return self._json("GET", f"/v1/jobs/{job_id}")

    def cancel(self, job_id: str) -> dict:
        return self._json("POST", f"/v1/jobs/{job_id}/cancel")

    def wait(
        self, job: Any, timeout: float = 600.0, progress: Optional[Callable[[str, int, int], Any]] = None
    ) -> dict:
        """Waits until a job ends (polling its view); ``progress(phase, converged, wanted)`` hears each change.
        A job that failed or was canceled raises its problem as a KacError."""
        view = job if isinstance(job, dict) else self.job(job)
        deadline = time.monotonic() + timeout
        last: Optional[tuple] = None
        while view["status"] not in TERMINAL:
            p = view.get("progress") or {}
            now = (str(p.get("phase", "")), int(p.get("converged", 0)), int(p.get("wanted", 0)))
            if progress is not None and now != last:
                progress(*now)
                last = now
            if time.monotonic() > deadline:
                raise TimeoutError(f"job {view['id']} still {view['status']} after {timeout} s")
            time.sleep(0.1)
            view = self.job(view["id"])
        if view["status"] != "succeeded":
            err = view.get("error") or {}
            raise _problem(err.get("status", 500), json.dumps(err).encode(), f"job {view['id']}")
        return view

    def result(self, result_id: str, arrays: bool = True) -> dict:
        """A finished result; with ``arrays``, each array of it as a NumPy array under ``result["arrays"][name]``
        (fetched from its ``.npy`` link) instead of its links."""
        r = self._json("GET", f"/v1/results/{result_id}", query={"values": "false"})
        return self._with_arrays(r) if arrays else r

    def _with_arrays(self, r: dict) -> dict:
        r["arrays"] = {name: self.array(link["npy"]) for name, link in (r.get("arrays") or {}).items()}
        return r

    def array(self, link: str) -> np.ndarray:
        """An array from its ``.npy`` link."""
        _, data, _ = self._request("GET", link)
        return np.load(io.BytesIO(data))

    def analyze(self, shape_id: str, analysis: str, timeout: float = 600.0, progress: Any = None, **request: Any) -> dict:
        """Submits, waits and reads: the result with its arrays as NumPy."""
        job = self.wait(self.submit(shape_id, analysis, **request), timeout, progress)
        return self.result(job["id"])

    # -- retrieval -------------------------------------------------------------------------------------------

    def search(self, shape_id: Optional[str] = None, fingerprint: Any = None, **request: Any) -> dict:
        """The stored shapes nearest to a stored shape or to a fingerprint (``POST /v1/search``)."""
        body: dict = dict(request)
        if shape_id is not None:
            body["shape_id"] = shape_id
        if fingerprint is not None:
            body["fingerprint"] = np.asarray(fingerprint, dtype=np.float64).tolist()
        return self._json("POST", "/v1/search", body, query={"wait": 60})

    def compare(self, shape_ids: list, **request: Any) -> dict:
        """Shape-DNA distances between stored shapes (``POST /v1/compare``), waited for."""
        return self._json("POST", "/v1/compare", {"shape_ids": shape_ids, **request}, query={"wait": 60})

    def correspondence(self, source_id: str, target_id: str, timeout: float = 600.0, **request: Any) -> dict:
        """Which vertex of the target each source vertex is; the result with its arrays as NumPy."""
        body = {"source_id": source_id, "target_id": target_id, **request}
        out = self._json("POST", "/v1/correspondence", body, query={"wait": 0})
        if "links" in out and "status" in out:
            return self.result(self.wait(out, timeout)["id"])
        return self._with_arrays(out)

    def analyses(self, shape_id: Optional[str] = None) -> dict:
        return self._json("GET", "/v1/analyses", query={"shape_id": shape_id})
