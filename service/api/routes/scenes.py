"""``/v1/scenes/import`` and ``/v1/scenes/export``: SPACAR ``.dat`` models in and out (model.spacar)."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter
from fastapi.exceptions import RequestValidationError
from fastapi.responses import PlainTextResponse

from ...jobs import worker
from ...jobs.worker import ComputationFailed
from ...schemas import SpacarExportRequest, SpacarImportRequest, SpacarImportResult
from ..errors import ERRORS
from ..guards import scene_from

__all__ = ["router"]


def _export(data: dict[str, Any], numbering: Any, warping: str = "factor") -> str:
    """The scene's .dat text; numbers that break the section arithmetic (a zero area from subnormal sizes)
    are named (422), never a 500 (the fuzzer of issue 29 found one: ZeroDivisionError in the section)."""
    from ....model.errors import FlexoptError
    from ....model.spacar import write_dat

    scene = scene_from(data)
    try:
        return write_dat(scene, numbering=numbering, warping=warping)
    except FlexoptError:
        raise
    except Exception as exc:  # noqa: BLE001 - arithmetic on extreme numbers: named, never a 500
        _, err = worker.broken(exc, scene.model_dump(mode="json"))
        raise ComputationFailed(err["field"], err["message"]) from None


def router(prefix: str) -> APIRouter:
    """The SPACAR import and export routes (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.post(
        "/scenes/import",
        response_model=SpacarImportResult,
        responses=ERRORS,
        summary="Read a SPACAR .dat model into a scene (every unmappable line a 422 naming it)",
    )
    async def import_dat(req: SpacarImportRequest) -> SpacarImportResult:
        from ....model.spacar import SpacarError, read_dat

        try:
            imp = await asyncio.to_thread(read_dat, req.text, req.name)  # off the event loop: a 1 MB file
        except SpacarError as exc:  # one error per line of the file that cannot be mapped
            raise RequestValidationError(
                [{"loc": ("body", "text"), "msg": m, "type": "value_error"} for m in exc.lines]
            ) from None
        scene = await asyncio.to_thread(scene_from, imp.scene)
        from ....model.spacar_dcc import spacar_dcc

        dcc = await asyncio.to_thread(spacar_dcc, imp.text)
        return SpacarImportResult(
            scene=scene.model_dump(mode="json"),
            mapped=imp.mapped,
            notes=imp.notes,
            numbering=imp.numbering,
            spacar_dof=imp.spacar_dof,
            released=imp.released,
            spacar=dcc.to_dict(),
        )

    @r.post(
        "/scenes/export",
        response_class=PlainTextResponse,
        responses=ERRORS,
        summary="Write a scene as a SPACAR .dat model",
    )
    async def export_dat(req: SpacarExportRequest) -> PlainTextResponse:
        return PlainTextResponse(await asyncio.to_thread(_export, req.scene, req.numbering, req.warping))

    return r
