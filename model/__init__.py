"""flexopt.model: SPACAR-style 3D flexure model in CasADi, stroke equilibrium and natural frequencies."""

from .constraints import ConstraintDiagnosis
from .curve import Analysis, frequency_curve
from .diagnosis import diagnose
from .errors import EquilibriumError, FlexoptError, KernelBuildError, ModelSizeError, SceneError
from .io import load_dat, load_scene, scene_from_dict
from .linear import StateSpace, frequency_response, state_space
from .results import Failure, FrequencyCurve
from .scene import Scene
from .spacar import SpacarImport, read_dat, spacar_light, write_dat
from .spacar_dcc import SpacarDcc, spacar_dcc
from .structure import MAX_DOFS, compile_scene
from .templates import DESIGN_SPACES, TEMPLATES, design_space, template, template_parameters

__all__ = [
    "Analysis",
    "frequency_curve",
    "ConstraintDiagnosis",
    "diagnose",
    "FlexoptError",
    "SceneError",
    "ModelSizeError",
    "EquilibriumError",
    "KernelBuildError",
    "load_scene",
    "load_dat",
    "scene_from_dict",
    "read_dat",
    "write_dat",
    "spacar_light",
    "SpacarImport",
    "spacar_dcc",
    "SpacarDcc",
    "state_space",
    "frequency_response",
    "StateSpace",
    "Failure",
    "FrequencyCurve",
    "Scene",
    "MAX_DOFS",
    "compile_scene",
    "TEMPLATES",
    "template",
    "template_parameters",
    "DESIGN_SPACES",
    "design_space",
]
