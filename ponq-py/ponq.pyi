"""Type stubs of the `ponq` extension module (PoNQ-rs for Python).

The docstrings of the functions themselves (``help(ponq.infer)``) describe every argument.
"""

import os
from typing import Any, Callable, Dict, Literal, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str
DEFAULT_MERGE_SMOOTH: float

Float64Array = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
Int64Array = npt.NDArray[np.int64]
Mesh = Tuple[Float64Array, Int64Array]
PoNQDict = Dict[str, Float64Array]
Bounds = Optional[Sequence[float]]
OpenArg = Union[None, bool, float]

@overload
def infer(
    sdf: npt.ArrayLike,
    *,
    bounds: Bounds = None,
    level: Optional[float] = None,
    inside: str = "auto",
    field: str = "auto",
    colours: None = None,
    model: Union[None, str, os.PathLike[str]] = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = 15.0,
    open: OpenArg = None,
    refine: str = "auto",
    threads: Optional[int] = None,
    return_ponq: Literal[False] = False,
    check: bool = True,
) -> Mesh: ...
@overload
def infer(
    sdf: npt.ArrayLike,
    *,
    bounds: Bounds = None,
    level: Optional[float] = None,
    inside: str = "auto",
    field: str = "auto",
    colours: None = None,
    model: Union[None, str, os.PathLike[str]] = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = 15.0,
    open: OpenArg = None,
    refine: str = "auto",
    threads: Optional[int] = None,
    return_ponq: Literal[True],
    check: bool = True,
) -> Tuple[Float64Array, Int64Array, PoNQDict]: ...
@overload
def infer(
    sdf: npt.ArrayLike,
    *,
    bounds: Bounds = None,
    level: Optional[float] = None,
    inside: str = "auto",
    field: str = "auto",
    colours: npt.ArrayLike,
    model: Union[None, str, os.PathLike[str]] = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = 15.0,
    open: OpenArg = None,
    refine: str = "auto",
    threads: Optional[int] = None,
    return_ponq: Literal[False] = False,
    check: bool = True,
) -> Tuple[Float64Array, Int64Array, Float64Array]: ...
@overload
def infer(
    sdf: npt.ArrayLike,
    *,
    bounds: Bounds = None,
    level: Optional[float] = None,
    inside: str = "auto",
    field: str = "auto",
    colours: npt.ArrayLike,
    model: Union[None, str, os.PathLike[str]] = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = 15.0,
    open: OpenArg = None,
    refine: str = "auto",
    threads: Optional[int] = None,
    return_ponq: Literal[True],
    check: bool = True,
) -> Tuple[Float64Array, Int64Array, Float64Array, PoNQDict]: ...
@overload
def infer_field(
    f: Callable[[Float64Array], npt.ArrayLike],
    res: int,
    *,
    bounds: Bounds = None,
    level: Optional[float] = None,
    inside: str = "auto",
    field: str = "auto",
    colour: None = None,
    lipschitz: float = 1.0,
    batch: int = 65536,
    model: Union[None, str, os.PathLike[str]] = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = 15.0,
    refine: str = "auto",
    threads: Optional[int] = None,
    check: bool = True,
) -> Tuple[Float64Array, Int64Array, Dict[str, Any]]: ...
@overload
def infer_field(
    f: Callable[[Float64Array], npt.ArrayLike],
    res: int,
    *,
    bounds: Bounds = None,
    level: Optional[float] = None,
    inside: str = "auto",
    field: str = "auto",
    colour: Callable[[Float64Array], npt.ArrayLike],
    lipschitz: float = 1.0,
    batch: int = 65536,
    model: Union[None, str, os.PathLike[str]] = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = 15.0,
    refine: str = "auto",
    threads: Optional[int] = None,
    check: bool = True,
) -> Tuple[Float64Array, Int64Array, Float64Array, Dict[str, Any]]: ...
def mesh(
    points: npt.ArrayLike,
    normals: npt.ArrayLike,
    quadrics: npt.ArrayLike,
    *,
    vstars: Optional[npt.ArrayLike] = None,
    grid_scale: float,
    bounds: Bounds = None,
    lite: bool = False,
    coarsen: int = 0,
    merge_smooth: Optional[float] = None,
    open: OpenArg = None,
    crease_flips: bool = True,
    threads: Optional[int] = None,
    check: bool = True,
) -> Mesh: ...
@overload
def sdf(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    res: int,
    *,
    normalize: bool = True,
    return_transform: Literal[False] = False,
    repair: bool = True,
    return_report: Literal[False] = False,
    threads: Optional[int] = None,
) -> Float32Array: ...
@overload
def sdf(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    res: int,
    *,
    normalize: bool = True,
    return_transform: Literal[True],
    repair: bool = True,
    return_report: Literal[False] = False,
    threads: Optional[int] = None,
) -> Tuple[Float32Array, Float64Array, float]: ...
@overload
def sdf(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    res: int,
    *,
    normalize: bool = True,
    return_transform: bool = False,
    repair: Literal[True] = True,
    return_report: Literal[True],
    threads: Optional[int] = None,
) -> Tuple[Any, ...]: ...
def sample(
    vertices: npt.ArrayLike, faces: npt.ArrayLike, n: int, *, seed: int = 0
) -> Tuple[Float64Array, Float64Array]: ...
@overload
def fit(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    *,
    grid: int = 32,
    iterations: int = 400,
    samples: Optional[int] = None,
    seed: int = 0,
    lite: bool = False,
    open: OpenArg = None,
    normalized: bool = False,
    return_ponq: Literal[False] = False,
    threads: Optional[int] = None,
    check: bool = True,
) -> Mesh: ...
@overload
def fit(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    *,
    grid: int = 32,
    iterations: int = 400,
    samples: Optional[int] = None,
    seed: int = 0,
    lite: bool = False,
    open: OpenArg = None,
    normalized: bool = False,
    return_ponq: Literal[True],
    threads: Optional[int] = None,
    check: bool = True,
) -> Tuple[Float64Array, Int64Array, PoNQDict]: ...
def metrics(
    pred_v: npt.ArrayLike,
    pred_f: npt.ArrayLike,
    gt_v: npt.ArrayLike,
    gt_f: npt.ArrayLike,
    *,
    samples: int = 100000,
    seed: int = 0,
    sharp_angle: float = 30.0,
    threads: Optional[int] = None,
) -> Dict[str, Any]: ...
def check(vertices: npt.ArrayLike, faces: npt.ArrayLike) -> Dict[str, Any]: ...
def marching_cubes(sdf: npt.ArrayLike, *, bounds: Bounds = None) -> Mesh: ...
def prepare_meshes(
    meshes: Sequence[Union[str, os.PathLike[str]]],
    out: Union[str, os.PathLike[str]],
    *,
    root: Union[None, str, os.PathLike[str]] = None,
    res: Sequence[int] = (32, 64),
    samples: int = 1000000,
    sample_seed: int = 0,
    repair: bool = True,
    shard: Union[None, str, Tuple[int, int]] = None,
    log: Union[None, bool, str, os.PathLike[str]] = None,
    threads: Optional[int] = None,
) -> list[Dict[str, Any]]: ...
def mesh_files(dir_or_list: Union[str, os.PathLike[str]]) -> Tuple[list[str], str]: ...
def output_names(
    meshes: Sequence[Union[str, os.PathLike[str]]], *, root: Union[None, str, os.PathLike[str]] = None
) -> list[str]: ...
