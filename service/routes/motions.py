"""/motions: upload, fetch (several formats), validation report."""

from __future__ import annotations

import math
from typing import Any, Literal

from fastapi import APIRouter, Depends, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response
from starlette.datastructures import UploadFile

from service import store
from service.config import Settings
from service.db import Database
from service.deps import app_settings, get_db, get_owner
from service.problems import Problem, not_found
from service.schemas import MotionOut, MotionPage
from service.uploads import (
    MAX_FILES,
    ImporterUnavailable,
    UploadError,
    classify,
    motion_from_trial,
    motion_from_upload,
    parse_json,
)
from service.views import motion_out

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
                    "properties": {
                        "files": {"type": "array", "items": {"type": "string", "format": "binary"},
                                  "description": "the trial: .osim + .mot (OpenSim), .c3d, .bvh or a DeepMimic .txt"},
                        "mass": {"type": "number", "exclusiveMinimum": 0, "description": "subject mass (kg), C3D"},
                        "belt_speed": {"type": "number", "description": "treadmill belt speed (m/s)"},
                        "name": {"type": "string", "maxLength": 200},
                    },
                }
            },
        },
    }
}

FORMATS = ("json", "gltf", "glb", "bvh", "motion")


def _form_float(form, key: str) -> float | None:
    v = form.get(key)
    if v is None or (isinstance(v, str) and not v.strip()):
        return None
    if not isinstance(v, str):
        raise UploadError(f"{key} must be a number, not a file")
    try:
        x = float(v)
    except ValueError:
        raise UploadError(f"{key} must be a number, got {v[:40]!r}") from None
    if not math.isfinite(x):
        raise UploadError(f"{key} must be finite")
    return x


def _store_motion(db: Database, owner: str, motion, name: str) -> dict:
    with db.write() as s:
        row = store.add_motion(s, owner=owner, motion=motion, kind=classify(motion), name=name)
        return motion_out(row)


@router.post(
    "/motions",
    status_code=201,
    response_model=MotionOut,
    summary="upload a motion (motion file v1 JSON) or a mocap trial (multipart)",
    openapi_extra=UPLOAD_BODY,
    responses={201: {"headers": {"Location": {"schema": {"type": "string"}}}},
               413: {"description": "body too large"}, 415: {"description": "unsupported content type"},
               501: {"description": "importer not available"}},
)
async def upload_motion(
    request: Request,
    name: str = Query("", max_length=200, description="a label for the motion"),
    owner: str = Depends(get_owner),
    db: Database = Depends(get_db),
) -> Response:
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    try:
        if ctype == "application/json" or ctype.endswith("+json"):
            body = await request.body()
            motion = await run_in_threadpool(lambda: motion_from_upload(parse_json(body)))
        elif ctype == "multipart/form-data":
            form = await request.form(max_files=MAX_FILES, max_fields=16)
            try:
                files = [(f.filename or "", await f.read()) for f in form.getlist("files") if isinstance(f, UploadFile)]
                mass, belt = _form_float(form, "mass"), _form_float(form, "belt_speed")
                label = form.get("name")
                if isinstance(label, str) and label:
                    name = label[:200]
            finally:
                await form.close()
            motion = await run_in_threadpool(lambda: motion_from_trial(files, mass=mass, belt_speed=belt))
        else:
            raise Problem(415, f"unsupported content type {ctype or '(none)'!r}: send application/json "
                          "(motion file v1) or multipart/form-data (mocap trial)")
    except UploadError as e:
        raise Problem(422, str(e)) from None
    except ImporterUnavailable as e:
        raise Problem(501, str(e)) from None
    out = await run_in_threadpool(_store_motion, db, owner, motion, name)
    if ctype == "multipart/form-data":
        out["input"] = (motion.provenance or {}).get("input")
    return JSONResponse(out, status_code=201, headers={"Location": out["links"]["self"]})


@router.get("/motions", response_model=MotionPage, summary="your motions, oldest first")
def list_motions(
    offset: int = Query(0, ge=0, le=10**9),
    limit: int | None = Query(None, ge=1, le=1000),
    owner: str = Depends(get_owner),
    db: Database = Depends(get_db),
    settings: Settings = Depends(app_settings),
) -> dict:
    limit = limit or settings.page_size
    with db.read() as s:
        rows, total = store.list_motions(s, owner=owner, offset=offset, limit=limit)
        items = [motion_out(r) for r in rows]
    nxt = f"/motions?offset={offset + limit}&limit={limit}" if offset + limit < total else None
    return dict(items=items, total=total, limit=limit, next=nxt)


def _option(v: str) -> Any:
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
        raise Problem(422, f"option value {v!r} is not finite")
    return x


@router.get(
    "/motions/{motion_id}",
    summary="a motion: JSON clip (default), glTF 2.0 binary (gltf = glb), BVH, or the motion file v1 "
            "(format=motion)",
    description="Other query parameters are the exporter's options (docs/export.md), e.g. `y_up=true`, "
                "`decimals=3` (json), `units=m` (bvh), `meshes=false` (gltf, glb), `binary=false` (gltf: "
                "the .gltf JSON with its buffer embedded, model/gltf+json, instead of the binary .glb).",
    responses={200: {"content": {"application/json": {}, "model/gltf+json": {}, "model/gltf-binary": {},
                                 "text/plain": {}}},
               404: {"description": "no such motion for this key"}, 501: {"description": "exporter not available"}},
)
def get_motion(
    motion_id: str,
    request: Request,
    format: Literal["json", "gltf", "glb", "bvh", "motion"] = Query(
        "json", description="output format (gltf and glb: binary glTF 2.0); other query parameters are the "
                            "exporter's options"),
    owner: str = Depends(get_owner),
    db: Database = Depends(get_db),
) -> Response:
    options = {k: _option(v) for k, v in request.query_params.items() if k != "format"}
    if format == "motion" and options:
        raise Problem(422, f"format=motion takes no options, got {sorted(options)}")
    cache = request.app.state.export_cache
    with db.read() as s:
        row = store.get_motion(s, motion_id=motion_id, owner=owner)
        if row is None:
            raise not_found("motion", motion_id)
        key = (row.sha256, format, tuple(sorted((k, repr(v)) for k, v in options.items())))
        hit = cache.get(key)
        if hit is not None:
            return Response(hit[0], media_type=hit[1])
        data = store.motion_json(row)
    if format == "motion":
        cache.put(key, data, "application/json")
        return Response(data, media_type="application/json")
    try:
        from solver.export import ExportError, export_motion, media_type
    except ImportError as e:
        raise Problem(501, f"exporters are not available in this build ({e})") from None
    import json

    from solver.motion import motion_from_dict

    motion = motion_from_dict(json.loads(data))
    try:
        out = export_motion(motion, format, **options)
        mt = media_type(format, **options)
    except ImportError as e:
        raise Problem(501, f"format {format!r} is not available in this build ({e})") from None
    except ExportError as e:
        raise Problem(422, str(e)) from None
    body = out.encode("utf-8") if isinstance(out, str) else out
    cache.put(key, body, mt)
    return Response(body, media_type=mt)


@router.get(
    "/motions/{motion_id}/validation",
    summary="plausibility report of a motion (MuJoCo replay included)",
    responses={404: {"description": "no such motion for this key"}, 501: {"description": "validator not available"}},
)
def get_validation(motion_id: str, owner: str = Depends(get_owner), db: Database = Depends(get_db)) -> dict:
    with db.read() as s:
        row = store.get_motion(s, motion_id=motion_id, owner=owner)
        if row is None:
            raise not_found("motion", motion_id)
        if row.validation is not None:
            return row.validation
        motion = store.load_motion(row)
    try:
        from mjcf.validate import validate  # noqa: F401
    except ImportError as e:
        raise Problem(501, f"the validator is not available in this build ({e})") from None
    from service.jobs import validation_report

    report = validation_report(motion)
    with db.write() as s:
        store.set_validation(s, motion_id=motion_id, report=report)
    return report
