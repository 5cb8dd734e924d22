"""Type stubs of the compiled half of photometeor; import photometeor instead."""

import os
from typing import Any, Callable, Dict, Optional, Union

from . import crystal_phase as crystal_phase
from . import mie as mie
from . import phase as phase
from . import refractive_index as refractive_index
from . import size_parameter as size_parameter

__version__: str

def bake_scene(
    out: Union[str, "os.PathLike[str]"],
    *,
    scene_path: Optional[Union[str, "os.PathLike[str]"]] = None,
    scene_text: Optional[str] = None,
    scene_json: Optional[str] = None,
    quality: Optional[str] = None,
    jobs: Optional[int] = None,
    progress: Optional[Callable[[str, int, int, str], Any]] = None,
) -> str: ...
def load_bake(dir: Union[str, "os.PathLike[str]"]) -> Dict[str, Any]: ...
def scene_toml(scene_json: str) -> str: ...
