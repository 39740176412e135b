"""``/v1/templates``: the parametric templates, their parameters, and the scene of a template; ``/v1/scene-schema``."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from ...schemas import ParameterInfo, Problem, TemplateInfo, TemplateSceneRequest
from ..errors import ERRORS

__all__ = ["router"]


def _parameter_info(name: str, default: Any, unit: str | None = None) -> ParameterInfo:
    if isinstance(default, str):
        from typing import get_args

        from ....model.scene import RectangularSection

        choices = (
            get_args(RectangularSection.model_fields[name].annotation)
            if (name in RectangularSection.model_fields)
            else ()
        )
        bounds = f"one of {', '.join(choices)}" if choices else "string"
        return ParameterInfo(name=name, type="string", default=default, bounds=bounds)
    if isinstance(default, int):
        return ParameterInfo(name=name, type="integer", default=default, bounds="integer >= 1 (a count)")
    bounds = "any real number (signed offset)" if "offset" in name else "positive (> 0)"
    if unit:
        bounds += f"; a number in {unit} or a string with a unit, e.g. '{default:g} {unit}'"
    return ParameterInfo(name=name, type="number", default=float(default), bounds=bounds, unit=unit)


def _unknown_template(name: str) -> str:
    from ....model.errors import SceneError
    from ....model.templates import template_parameters

    try:
        template_parameters(name)
    except SceneError as exc:
        return exc.message  # "unknown template 'x' (did you mean 'y'?); choose one of ..."
    return f"unknown template '{name}'"  # pragma: no cover - only called for unknown names


def _template_info(name: str) -> TemplateInfo:
    from ....model import template_parameters
    from ....model.templates import parameter_unit

    params = template_parameters(name)
    return TemplateInfo(
        name=name, parameters=[_parameter_info(k, v, parameter_unit(name, k)) for k, v in params.items()]
    )


def router(prefix: str) -> APIRouter:
    """The template and scene-schema routes (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.get("/templates", response_model=list[TemplateInfo], summary="List parametric templates")
    async def list_templates() -> list[TemplateInfo]:
        from ....model import TEMPLATES

        return [_template_info(n) for n in sorted(TEMPLATES)]

    @r.get(
        "/templates/{name}",
        response_model=TemplateInfo,
        summary="One template: parameters, defaults, bounds",
        responses={404: {"model": Problem}},
    )
    async def get_template(name: str) -> TemplateInfo:
        from ....model import TEMPLATES

        if name not in TEMPLATES:
            raise HTTPException(404, _unknown_template(name))
        return _template_info(name)

    @r.post(
        "/templates/{name}/scene",
        summary="The scene of a template with parameters overridden",
        response_model=dict[str, Any],
        responses={404: {"model": Problem}, **ERRORS},
    )
    async def template_scene(name: str, body: TemplateSceneRequest | None = None) -> JSONResponse:
        from ....model import TEMPLATES, template
        from ....model.errors import SceneError

        if name not in TEMPLATES:
            raise HTTPException(404, _unknown_template(name))
        params = body.parameters if body is not None else {}
        try:
            scene = template(name, **params)
        except SceneError as exc:
            key = exc.field.removeprefix("template.")
            loc = ("body", "parameters", key) if exc.field.startswith("template.") else ("body", "parameters")
            raise RequestValidationError([{"loc": loc, "msg": exc.message, "type": "value_error"}]) from None
        return JSONResponse(scene.model_dump(mode="json"))

    @r.get("/scene-schema", summary="JSON schema of a scene", response_model=dict[str, Any])
    async def scene_schema() -> dict[str, Any]:
        from ....model.scene import Scene

        return Scene.model_json_schema()

    return r
