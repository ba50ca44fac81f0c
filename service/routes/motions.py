"""/motions: upload, fetch (several formats), validation report.

The heavy parts (parsing and validating an upload, exports, the plausibility report) run in
the API's compute processes (:mod:`service.work`), never on the event loop.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import zlib
from collections.abc import Iterator
from typing import Any, Literal

from fastapi import APIRouter, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response, StreamingResponse
from starlette.concurrency import iterate_in_threadpool
from starlette.datastructures import UploadFile

from service import limits, quota, store, uploads, work
from service.config import Settings
from service.db import Database
from service.deps import QUOTA_429, UNAVAILABLE_503, DatabaseDep, OffsetPageDep, OwnerDep, SettingsDep
from service.limits import clip
from service.models import MotionRow
from service.problems import Problem, known_id, not_found
from service.schemas import ExportChoices, MotionOut, MotionPage
from service.uploads import MAX_FILES, Encoded, ImporterUnavailable, UploadError
from service.views import motion_out
from service.work import Compute
from solver.formats import BVH_UNITS, EXPORTERS, export_media_types

router = APIRouter(tags=["motions"])

UPLOAD_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/MotionFileV1"}},
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["files"],
                    "additionalProperties": False,
                    "properties": {
                        "files": {"type": "array", "items": {"type": "string", "format": "binary"},
                                  "minItems": 1, "maxItems": MAX_FILES,
                                  "description": "the trial: .osim + .mot (OpenSim), .c3d, .bvh or a DeepMimic .txt"},
                        "mass": {"type": "number", "minimum": 1, "maximum": 500,
                                 "description": "subject mass (kg): C3D without it, BVH"},
                        "belt_speed": {"type": "number", "minimum": 0, "maximum": 20,
                                       "description": "treadmill belt speed (m/s, 0 to 20); for a BVH or glTF clip "
                                                      "that walks in place (no root motion), its walking speed "
                                                      "(default: detected from the stance foot; 0: not in place)"},
                        "lower_only": {"type": "boolean",
                                       "description": "fit the lower body only (default: the whole body when the "
                                                      "data allow)"},
                        "markers": {"type": "string", "maxLength": 4000, "pattern": "^[^\\x00-\\x1f\\x7f]*$",
                                    "description": "C3D: marker mapping ROLE=label,... for unrecognised marker sets "
                                                   "(Plug-in Gait roles, e.g. LASI=L_IAS,RASI=R_IAS)"},
                        "units": {"type": "string", "enum": list(BVH_UNITS),
                                  "description": "BVH: the file's length unit (default: auto)"},
                        "up": {"type": "string", "enum": ["y", "z"], "description": "BVH: the file's up axis "
                                                                                       "(default: y)"},
                        "joints": {"type": "string", "maxLength": 4000, "pattern": "^[^\\x00-\\x1f\\x7f]*$",
                                   "description": "BVH: joint mapping ROLE=NAME,... for unrecognised joint names "
                                                  "(roles hips, hip_l, knee_l, ankle_l, mtp_l, …, e.g. "
                                                  "hip_l=Thigh_L,knee_l=Shin_L)"},
                        "in_degrees": {"type": "boolean", "description": "OpenSim: the coordinates are in degrees "
                                                                          "(default: the file's header says)"},
                        "name": {"type": "string", "maxLength": 200, "pattern": "^[^\\x00-\\x1f\\x7f]*$"},
                    },
                }
            },
        },
    }
}

#: the exporters' registry (solver.formats), and the motion file itself
FORMATS = (*EXPORTERS, "motion")
ExportFormat = Literal[FORMATS]  # type: ignore[valid-type]
MULTIPART_FIELDS = ("files", "mass", "belt_speed", *uploads.OPTION_FIELDS, "name")
NAME_PATTERN = r"^[^\x00-\x1f\x7f]*$"
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def _form_float(form, key: str) -> float | None:
    v = form.get(key)
    if v is None or (isinstance(v, str) and not v.strip()):
        return None
    if not isinstance(v, str):
        raise UploadError(f"{key} must be a number, not a file")
    try:
        x = float(v)
    except ValueError:
        raise UploadError(f"{key} must be a number, got {clip(v, 40)!r}") from None
    if not math.isfinite(x):
        raise UploadError(f"{key} must be finite")
    return x


def _label(v: object) -> str:
    if not isinstance(v, str):
        raise UploadError("name must be text, not a file")
    if len(v) > limits.MAX_NAME_CHARS or _CONTROL.search(v):
        raise UploadError(f"name must be at most {limits.MAX_NAME_CHARS} characters without control characters")
    return v


def _store_motion(db: Database, settings: Settings, owner: str, encoded: Encoded, name: str) -> dict:
    with db.write() as s:
        quota.check_storage(s, settings, owner=owner, adding=len(encoded.data))
        row = store.add_encoded(s, owner=owner, encoded=encoded, name=name)
        return motion_out(row)


def _storage_left(db: Database, settings: Settings, owner: str) -> None:
    with db.read() as s:
        quota.check_storage(s, settings, owner=owner)


def _upload_memo(kind: str, *parts: Any) -> tuple[str, str]:
    """The key under which an upload's failure is remembered: its bytes and options."""
    h = hashlib.sha256()
    for p in parts:
        h.update(repr(p).encode() if not isinstance(p, bytes) else p)
        h.update(b"\0")
    return kind, h.hexdigest()


@router.post(
    "/motions",
    status_code=201,
    response_model=MotionOut,
    summary="upload a motion (motion file v2 JSON) or a mocap trial (multipart)",
    description="The upload is parsed and validated in the server's compute processes (time and memory limits). "
                "Schema-valid uploads are refused with 422 when the data is inconsistent (frame widths, unknown "
                "joints, a character that is not physical) or beyond the limits of docs/service.md (a capture "
                f"lasts at most {limits.MAX_CAPTURE_S:g} s and {limits.MAX_CAPTURE_FRAMES} frames, "
                f"{limits.MAX_COORDINATES} coordinates).",
    openapi_extra=UPLOAD_BODY,
    responses={201: {"headers": {"Location": {"schema": {"type": "string"}}}},
               413: {"description": "body too large"}, 415: {"description": "unsupported content type"},
               422: {"description": "invalid upload: malformed, inconsistent, not physical, or beyond the limits"},
               429: QUOTA_429,
               501: {"description": "importer not available"},
               503: UNAVAILABLE_503},
)
async def upload_motion(
    request: Request,
    owner: OwnerDep,
    db: DatabaseDep,
    settings: SettingsDep,
    name: str = Query("", max_length=limits.MAX_NAME_CHARS, pattern=NAME_PATTERN,
                      description="a label for the motion"),
) -> Response:
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    compute: Compute = request.app.state.compute
    await run_in_threadpool(_storage_left, db, settings, owner)  # a key over its storage computes nothing
    try:
        if ctype == "application/json" or ctype.endswith("+json"):
            body = await request.body()
            encoded = await compute.run(uploads.motion_upload, body, what="the upload", owner=owner, request=request,
                                        memo=_upload_memo("motion", body))
        elif ctype == "multipart/form-data":
            form = await request.form(max_files=MAX_FILES, max_fields=24)
            try:
                unknown = sorted({k for k in form if k not in MULTIPART_FIELDS})
                if unknown:
                    raise UploadError(f"unknown form field(s) {clip(str(unknown), 120)}; the fields are "
                                      f"{', '.join(MULTIPART_FIELDS)}")
                repeated = sorted(k for k in set(form.keys()) if k != "files" and len(form.getlist(k)) > 1)
                if repeated:
                    raise UploadError(f"form field(s) {', '.join(repeated)} given more than once; each option is "
                                      "given once (only 'files' repeats)")
                files = [(f.filename or "", await f.read()) for f in form.getlist("files") if isinstance(f, UploadFile)]
                mass, belt = _form_float(form, "mass"), _form_float(form, "belt_speed")
                texts = {k: form.get(k) for k in uploads.OPTION_FIELDS if form.get(k) is not None}
                if any(not isinstance(v, str) for v in texts.values()):
                    raise UploadError(f"{', '.join(k for k, v in texts.items() if not isinstance(v, str))}: a value, "
                                      "not a file")
                options = uploads.trial_options(texts)
                label = form.get("name")
                if label is not None:
                    name = _label(label)
            finally:
                await form.close()
            encoded = await compute.run(uploads.trial_upload, files, mass, belt, options, what="the trial import",
                                        owner=owner, request=request,
                                        memo=_upload_memo("trial", *(x for f in files for x in f), mass, belt,
                                                          sorted(options.items())))
        else:
            raise Problem(415, f"unsupported content type {clip(ctype, 60) or '(none)'!r}: send application/json "
                          "(motion file v2) or multipart/form-data (mocap trial)")
    except UploadError as e:
        raise Problem(422, str(e)) from None
    except ImporterUnavailable as e:
        raise Problem(501, str(e)) from None
    out = await run_in_threadpool(_store_motion, db, settings, owner, encoded, name)
    if ctype == "multipart/form-data":
        out["input"] = encoded.input
    return JSONResponse(out, status_code=201, headers={"Location": out["links"]["self"]})


@router.get("/motions", response_model=MotionPage, summary="your motions, oldest first")
def list_motions(page: OffsetPageDep, owner: OwnerDep, db: DatabaseDep) -> dict:
    with db.read() as s:
        rows, total = store.list_motions(s, owner=owner, offset=page.offset, limit=page.limit)
        items = [motion_out(r) for r in rows]
    return page.answer("/motions", items, total)


def _option(k: str, v: str) -> Any:
    if len(k) > 64 or len(v) > 256 or _CONTROL.search(k + v):
        raise Problem(422, f"exporter option {clip(k, 40)!r}: names and values are at most 64 and 256 "
                      "characters without control characters")
    lv = v.strip().lower()
    if lv in ("true", "false"):
        return lv == "true"
    if lv in ("none", "null"):
        return None
    try:
        return int(v)
    except ValueError:
        pass
    try:
        x = float(v)
    except ValueError:
        return v
    if not math.isfinite(x):
        raise Problem(422, f"option value {clip(v, 40)!r} is not finite")
    return x


@router.get(
    "/motions/{motion_id}",
    summary="a motion: JSON clip (default), glTF 2.0 binary (gltf = glb), BVH, or the motion file v2 "
            "(format=motion)",
    description="Other query parameters are the exporter's options (docs/export.md), e.g. `y_up=true`, "
                "`decimals=3` (json), `units=m` (bvh), `meshes=false` (gltf, glb), `binary=false` (gltf: "
                "the .gltf JSON with its buffer embedded, model/gltf+json, instead of the binary .glb), "
                "`rig=source` (bvh, gltf, glb: on the input's own skeleton), `world=gravity` (the default of "
                "json, gltf, glb, bvh and deepmimic: gravity points down and the walk stands on its ground, a slope "
                "walk on its ramp; the GLB holds the ground as a node 'ground', the clip as 'ground') or "
                "`world=ground` (the solver's frame: level ground, a slope as tilted gravity). "
                "An option the exporter does not know, or a value it refuses, gets 422. Exports are computed "
                "in the server's compute processes and cached by content.",
    responses={200: {"content": {mt: {} for mt in ("application/json", *export_media_types())}},
               404: {"description": "no such motion for this key"},
               422: {"description": "an exporter option it does not know or a value it refuses"},
               429: QUOTA_429,
               501: {"description": "exporter not available"},
               503: UNAVAILABLE_503},
)
async def get_motion(
    motion_id: str,
    request: Request,
    owner: OwnerDep,
    db: DatabaseDep,
    format: ExportFormat = Query(
        "json", description="output format (gltf and glb: binary glTF 2.0); other query parameters are the "
                            "exporter's options"),
) -> Response:
    known_id("motion", motion_id)
    options = {k: _option(k, v) for k, v in request.query_params.items() if k != "format"}
    if format == "motion" and options:
        raise Problem(422, f"format=motion takes no options, got {clip(str(sorted(options)), 200)}")
    compute: Compute = request.app.state.compute

    if format == "motion":  # the stored file, streamed from SQL and decompressed on the way
        size = await run_in_threadpool(_stored_size, db, motion_id, owner)
        return StreamingResponse(iterate_in_threadpool(_motion_file_chunks(db, motion_id, size)),
                                 media_type="application/json")

    def load() -> tuple[str, bytes]:
        with db.read() as s:
            row = store.get_motion(s, motion_id=motion_id, owner=owner)
            if row is None:
                raise not_found("motion", motion_id)
            return row.sha256, row.data

    sha, data = await run_in_threadpool(load)
    key = (sha, format, tuple(sorted((k, repr(v)) for k, v in options.items())))
    body, mt = await compute.cached(key, work.export, data, format, options, what=f"the {format} export",
                                    owner=owner, request=request)
    return Response(body, media_type=mt)


#: bytes read from SQL at a time by a download
CHUNK = 256 * 1024


def _stored_size(db: Database, motion_id: str, owner: str) -> int:
    with db.read() as s:
        row = store.get_motion(s, motion_id=motion_id, owner=owner)
        if row is None:
            raise not_found("motion", motion_id)
        return int(row.size or 0) or int(store.blob_size(s, MotionRow.data, MotionRow.id, motion_id) or 0)


def _motion_file_chunks(db: Database, motion_id: str, size: int) -> Iterator[bytes]:
    """The stored motion file, decompressed chunk by chunk as it is read from SQL."""
    z = zlib.decompressobj()
    for off in range(0, size, CHUNK):
        with db.read() as s:
            part = store.blob_chunk(s, MotionRow.data, (MotionRow.id == motion_id,), off, CHUNK)
        if not part:
            break
        out = z.decompress(part)
        if out:
            yield out
    tail = z.flush()
    if tail:
        yield tail


@router.delete(
    "/motions/{motion_id}",
    status_code=204,
    response_class=Response,
    summary="delete a motion and what hangs on it: its tutors, the jobs started from it (their λ optima and "
            "progress), its libraries and simulations",
    responses={204: {"description": "deleted"}, 404: {"description": "no such motion for this key"},
               409: {"description": "a job on it is still queued or running: cancel it first"}},
)
def delete_motion(motion_id: str, owner: OwnerDep, db: DatabaseDep) -> Response:
    known_id("motion", motion_id)
    with db.write() as s:
        if store.get_motion(s, motion_id=motion_id, owner=owner, lock=True) is None:
            raise not_found("motion", motion_id)
        delete_planned(s, store.deletion(s, motions=[motion_id]), f"motion {motion_id}")
    return Response(status_code=204)


def delete_planned(s, plan: store.Deletion, what: str) -> None:
    """Delete ``plan``, or 409 while one of its jobs is queued or running."""
    active = plan.active_jobs(s)
    if active:
        raise Problem(409, f"{what} has jobs still queued or running ({', '.join(active)}): cancel them "
                      "(POST /jobs/{id}/cancel) and delete it once they have ended")
    store.delete_all(s, plan)


@router.get(
    "/motions/{motion_id}/exports",
    response_model=ExportChoices,
    summary="what a motion can be downloaded as: its formats, and those on the input's own skeleton",
    description="One entry per distinct file (glb is gltf's file); deepmimic and opensim only for a motion made "
                "from a trial of that kind, rig=source only for a motion that carries the input's skeleton "
                "(a BVH, glTF or DeepMimic trial). The web page offers exactly these buttons.",
    responses={404: {"description": "no such motion for this key"}},
)
async def get_exports(motion_id: str, owner: OwnerDep, db: DatabaseDep) -> dict:
    known_id("motion", motion_id)
    from solver.export import export_choices
    from solver.motion import MotionContext

    def load() -> dict:
        with db.read() as s:
            row = store.get_motion(s, motion_id=motion_id, owner=owner)
            if row is None:
                raise not_found("motion", motion_id)
            data = row.data
        provenance = json.loads(zlib.decompress(data)).get("provenance") or {}
        context, provenance = MotionContext.split(provenance if isinstance(provenance, dict) else {})
        return export_choices(context, provenance)

    return await run_in_threadpool(load)


@router.get(
    "/motions/{motion_id}/validation",
    summary="plausibility report of a motion (MuJoCo replay included)",
    description="Stored with the motion: λ optima get it from their job; for uploads it is computed on the first "
                "request (in the server's compute processes) and stored.",
    responses={404: {"description": "no such motion for this key"},
               429: QUOTA_429,
               501: {"description": "validator not available"},
               503: UNAVAILABLE_503},
)
async def get_validation(motion_id: str, request: Request, owner: OwnerDep, db: DatabaseDep) -> dict:
    known_id("motion", motion_id)

    def load() -> tuple[dict | None, bytes | None]:
        with db.read() as s:
            row = store.get_motion(s, motion_id=motion_id, owner=owner)
            if row is None:
                raise not_found("motion", motion_id)
            if row.validation is not None and "sections" in row.validation:  # a report with its sections listed
                return row.validation, None
            return None, row.data

    report, data = await run_in_threadpool(load)
    if report is not None:
        return report
    compute: Compute = request.app.state.compute
    report = await compute.single(("validation", motion_id), work.validation, data, what="the plausibility report",
                                  owner=owner, request=request)

    def save() -> None:
        with db.write() as s:
            store.set_validation(s, motion_id=motion_id, report=report)

    await run_in_threadpool(save)
    return report
