"""``/v1/scenes/import`` and ``/v1/scenes/export``: SPACAR ``.dat`` models in and out (model.spacar)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.exceptions import RequestValidationError
from fastapi.responses import PlainTextResponse

from ...schemas import SpacarExportRequest, SpacarImportRequest, SpacarImportResult
from ..errors import ERRORS
from ..guards import scene_from

__all__ = ["router"]


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
            imp = read_dat(req.text, req.name)
        except SpacarError as exc:  # one error per line of the file that cannot be mapped
            raise RequestValidationError(
                [{"loc": ("body", "text"), "msg": m, "type": "value_error"} for m in exc.lines]
            ) from None
        scene = scene_from(imp.scene)
        from ....model.spacar_dcc import spacar_dcc

        return SpacarImportResult(
            scene=scene.model_dump(mode="json"),
            mapped=imp.mapped,
            notes=imp.notes,
            numbering=imp.numbering,
            spacar_dof=imp.spacar_dof,
            released=imp.released,
            spacar=spacar_dcc(imp.text).to_dict(),
        )

    @r.post(
        "/scenes/export",
        response_class=PlainTextResponse,
        responses=ERRORS,
        summary="Write a scene as a SPACAR .dat model",
    )
    async def export_dat(req: SpacarExportRequest) -> PlainTextResponse:
        from ....model.spacar import write_dat

        return PlainTextResponse(write_dat(scene_from(req.scene), numbering=req.numbering))

    return r
