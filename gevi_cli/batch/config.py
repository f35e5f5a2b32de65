"""Parse and validate a batch config (YAML) into typed dataclasses, naming the config line on errors.

Every problem is a :class:`GeviError` ``<config>:<line>: <key>: <problem>`` raised before any run
starts.  Relative paths resolve against ``root:`` (itself relative to the config file's folder;
default: the config file's folder).  The ready configs in ``configs/batch/`` set ``root: ../..`` so
that their paths read as from the repository root (``../shared/data/...``).  Schema: docs/batch.md.
"""
from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from gevi_cli.errors import GeviError

TOP_KEYS = {"name", "root", "trials", "output", "cache", "methods", "sequences", "baselines", "eval"}
SEQ_KEYS = {"name", "path", "simulate", "gt", "calib", "imu_calib", "kind", "cameras", "topics", "start", "max_frames",
            "stride", "methods", "optional", "seed_per_trial"}
SIM_KEYS = {"preset", "seed", "duration", "rate", "resolution", "baseline", "format", "imu_rate", "gyro_noise",
            "gyro_walk", "acc_noise", "acc_walk", "no_imu_noise", "distortion", "image_noise", "supersample", "a_max",
            "moving_start", "disparity_shift"}
METHOD_KEYS = {"name", "run", "trials"}
BASELINE_KEYS = {"name", "path", "file", "format", "frame", "T_B_C0", "stamps", "optional", "sequences"}
EVAL_KEYS = {"rpe_delta", "min_coverage", "max_diff", "plots", "online"}
FORMATS = ("tum", "euroc", "kitti", "kitti-idx")


@dataclass(frozen=True)
class SimSpec:
    """A `gevi simulate` render: preset, seed and options (seconds, Hz, pixels, metres)."""

    preset: str
    seed: int = 0
    duration_s: float | None = None
    rate_hz: float | None = None
    resolution: tuple | None = None
    baseline_m: float | None = None
    fmt: str = "euroc"
    imu: tuple = ()  # (key, value) pairs of ImuParams overrides; ("no_imu_noise", True) for a perfect IMU
    distortion: bool = True
    image_noise: bool = True
    supersample: int = 2
    a_max: float | None = None
    moving_start: bool = False
    disparity_shift_px: float = 0.0


@dataclass(frozen=True)
class RunInputs:
    """The `gevi run` input options of a sequence (paths resolved): what every run on it is given."""

    gt: str | None = None
    calib: str | None = None
    imu_calib: str | None = None
    kind: str | None = None
    cameras: str | None = None
    topics: str | None = None
    start: int = 0
    max_frames: int | None = None
    stride: int = 1  # every stride-th frame (`gevi run --stride`)

    def request_kwargs(self) -> dict:
        """As :class:`~gevi_cli.run.session.RunRequest` fields."""
        return {"groundtruth": self.gt, "calib": self.calib, "imu_calib": self.imu_calib, "kind": self.kind,
                "cameras": self.cameras, "topics": self.topics, "start": self.start, "max_frames": self.max_frames,
                "stride": self.stride}


@dataclass(frozen=True)
class SequenceEntry:
    """One sequence: a dataset ``path`` or a ``sim`` render, with the `gevi run` input options."""

    name: str
    line: int
    path: str | None = None
    sim: SimSpec | None = None
    inputs: RunInputs = RunInputs()
    methods: tuple | None = None  # names of the methods run on it (None: all)
    optional: bool = False  # a missing path is skipped with the reason instead of a config error
    seed_per_trial: bool = False  # simulated: trial k is rendered with seed k (scene, motion and noise)
    skip_reason: str = ""  # set for an optional sequence whose path is absent


@dataclass(frozen=True)
class MethodEntry:
    """A method with its option set, e.g. ``gevi --no-adaptive``; ``args`` are `gevi run` options."""

    name: str
    args: tuple
    trials: int
    line: int
    params: tuple = ()  # (RunRequest field, value) pairs parsed from args

    @property
    def ident(self) -> str:
        """Folder name of the method in the results tree."""
        return slug(self.name)

    @property
    def method(self) -> str:
        return dict(self.params).get("method") or ""


@dataclass(frozen=True)
class BaselineEntry:
    """Trajectories of another system: ``path`` template with ``{sequence}`` (or ``{stride}``, the
    sequence's ``stride:``, with ``sequences:``); frame and extrinsic.

    ``files``: one trajectory per run of the system (several: its trials, one table cell).
    ``T_B_C0``: ``sequence`` (the sequence's calibration), ``identity``, a file (text/YAML, as
    ``gevi eval --T-B-C0``) or a 4x4 list.  ``stamps``: ``sequence`` stamps KITTI rows (no times) with
    the times of the frames the runs are given (after ``start``, ``stride``, ``max_frames``), one row
    per frame.  A sequence whose folder is absent is ``n/a``; a folder without the file means the
    system ran and wrote nothing (``failed``).
    """

    name: str
    line: int
    path: str
    files: tuple  # file names inside the folder (empty: ``path`` is the file)
    fmt: str | None
    frame: str
    T_B_C0: object
    stamps: str | None = None  # None (the file's own) or "sequence"
    sequences: tuple | None = None
    optional: bool = False
    skip_reason: str = ""

    @property
    def ident(self) -> str:
        return slug(self.name)


@dataclass(frozen=True)
class EvalOptions:
    rpe_delta: float = 1.0  # frames
    min_coverage: float = 0.9  # fraction of the GT time span
    max_diff_s: float = 0.01
    plots: bool = True
    online: bool = False  # also evaluate each run's online (tracking-time) trajectory, traj_online_body.tum


@dataclass
class BatchConfig:
    name: str
    path: Path
    root: Path
    trials: int
    methods: list
    sequences: list
    baselines: list
    eval: EvalOptions
    output: str | None = None
    cache: str | None = None
    raw: dict = field(default_factory=dict)

    def resolve(self, p: str) -> Path:
        """``p`` against ``root``; ``../shared/data/...`` under ``$GEVI_SHARED_DATA`` when that is set."""
        from gevi_cli.shared_data import redirect

        q = Path(p).expanduser()
        return q if q.is_absolute() else (redirect(q) or self.root / q)

    def method(self, name: str) -> MethodEntry:
        return next(m for m in self.methods if m.name == name)


def slug(name: str) -> str:
    import re

    s = re.sub(r"[^A-Za-z0-9._+-]+", "_", name.replace("--", "")).strip("_")
    return s or "method"


# ----------------------------------------------------------------------------------- YAML with lines
def _compose(path: Path):
    """The config's YAML nodes (for line numbers), read as every YAML file of the project is read."""
    from gevi_cli.datasets.yamlio import YamlLoader, yaml_error, yaml_text

    loader = YamlLoader(yaml_text(path, "batch config"))
    try:
        node = loader.get_single_node()
        if node is not None:
            loader.construct_document(node)  # the constructors refuse duplicate keys, at their line
    except yaml.YAMLError as exc:
        raise yaml_error(path, exc) from None
    finally:
        loader.dispose()
    if node is None:
        raise GeviError(path, "is empty; expected methods: and sequences:")
    return node


def _value(node):
    return yaml.SafeLoader("").construct_object(node, deep=True) if node is not None else None


class _Ctx:
    def __init__(self, path: Path):
        self.path = path

    def err(self, node, key: str, msg: str) -> GeviError:
        line = node.start_mark.line + 1 if node is not None else 0
        return GeviError(f"{self.path}:{line}" if line else self.path, f"{key}: {msg}" if key else msg)

    def mapping(self, node, where: str, allowed: set) -> dict:
        """{key: (key node, value node)}; unknown keys are an error naming their line."""
        if not isinstance(node, yaml.MappingNode):
            raise self.err(node, where, "expected a mapping (key: value)")
        out = {}
        for k, v in node.value:
            key = _value(k)
            if key not in allowed:
                raise self.err(k, f"{where}.{key}" if where else str(key),
                               f"unknown key; allowed: {', '.join(sorted(allowed))}")
            if key in out:
                raise self.err(k, f"{where}.{key}" if where else str(key), "given twice")
            out[key] = (k, v)
        return out

    def scalar(self, entry: dict, key: str, where: str, typ, default=None, check=None):
        if key not in entry:
            return default
        _, v = entry[key]
        val = _value(v)
        if val is None:
            return default
        if typ is float and isinstance(val, int) and not isinstance(val, bool):
            val = float(val)
        if typ is not None and (not isinstance(val, typ) or (typ is int and isinstance(val, bool))):
            raise self.err(v, f"{where}.{key}", f"expected {getattr(typ, '__name__', typ)}, got {val!r}")
        if check is not None:
            problem = check(val)
            if problem:
                raise self.err(v, f"{where}.{key}", problem)
        return val


def _positive(v):
    return None if v > 0 else f"must be positive, got {v!r}"


# -------------------------------------------------------------------------------------------- parse
def load_batch_config(path) -> BatchConfig:
    """Read and check ``path``; every error names the line (see module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise GeviError(path, "no such batch config file")
    ctx = _Ctx(path)
    top_node = _compose(path)
    top = ctx.mapping(top_node, "", TOP_KEYS)
    root_s = ctx.scalar(top, "root", "", str, ".")
    root = (path.parent / root_s).resolve() if not Path(root_s).is_absolute() else Path(root_s)
    if not root.is_dir():
        raise ctx.err(top["root"][1], "root", f"{root}: no such folder")
    trials = ctx.scalar(top, "trials", "", int, 1, lambda v: None if v >= 1 else "must be at least 1")
    name = ctx.scalar(top, "name", "", str, path.stem)
    cfg = BatchConfig(name=name, path=path, root=root, trials=trials, methods=[], sequences=[], baselines=[],
                      eval=EvalOptions(), output=ctx.scalar(top, "output", "", str),
                      cache=ctx.scalar(top, "cache", "", str))
    if "eval" in top:
        ev = ctx.mapping(top["eval"][1], "eval", EVAL_KEYS)
        cfg.eval = EvalOptions(rpe_delta=ctx.scalar(ev, "rpe_delta", "eval", float, 1.0, _positive),
                               min_coverage=ctx.scalar(ev, "min_coverage", "eval", float, 0.9,
                                                       lambda v: None if 0 <= v <= 1 else "must be a fraction 0..1"),
                               max_diff_s=ctx.scalar(ev, "max_diff", "eval", float, 0.01, _positive),
                               plots=ctx.scalar(ev, "plots", "eval", bool, True),
                               online=ctx.scalar(ev, "online", "eval", bool, False))
    for key in ("methods", "sequences"):
        if key not in top:
            raise ctx.err(top_node, key, "missing; a batch needs methods: and sequences:")
    cfg.methods = _methods(ctx, top["methods"][1], trials)
    cfg.sequences = _sequences(ctx, top["sequences"][1], cfg)
    cfg.baselines = _baselines(ctx, top["baselines"][1], cfg) if "baselines" in top else []
    names = {m.name for m in cfg.methods}
    for b in cfg.baselines:
        if b.name in names or b.ident in {m.ident for m in cfg.methods}:
            raise ctx.err(None, f"baselines.{b.name}", "has the name of a method")
    return cfg


def _seq_list(ctx, node, key):
    if not isinstance(node, yaml.SequenceNode) or not node.value:
        raise ctx.err(node, key, "expected a non-empty list")
    return node.value


def _methods(ctx, node, trials) -> list:
    from gevi_cli.pipelines.config import METHODS
    from gevi_cli.run.method_options import check_method_config, parse_method_args

    out = []
    for item in _seq_list(ctx, node, "methods"):
        if isinstance(item, yaml.ScalarNode):
            text, name, n = str(_value(item)), None, trials
        else:
            m = ctx.mapping(item, "methods[]", METHOD_KEYS)
            text = ctx.scalar(m, "run", "methods[]", str)
            if text is None:
                raise ctx.err(item, "methods[].run", "missing, e.g. run: cfo --pnp epnp")
            name = ctx.scalar(m, "name", "methods[]", str)
            n = ctx.scalar(m, "trials", "methods[]", int, trials, lambda v: None if v >= 1 else "must be at least 1")
        try:
            words = shlex.split(text)
        except ValueError as exc:
            raise ctx.err(item, "methods", f"{text!r}: {exc}") from None
        if not words or words[0] not in METHODS:
            raise ctx.err(item, "methods", f"unknown method {words[0] if words else text!r}; choose one of "
                                           f"{', '.join(METHODS)} followed by its options")
        where = f"{ctx.path}:{item.start_mark.line + 1}"
        try:
            params = parse_method_args(["--method", words[0], *words[1:]], where)
        except GeviError as exc:
            raise GeviError(exc.where, f"methods: {text!r}: {exc.message}") from None
        try:  # the configuration it makes, checked as `gevi run` checks it (the input's kind: per sequence, later)
            check_method_config(params)
        except GeviError as exc:
            raise GeviError(where, f"methods: {text!r}: {exc.one_line()}") from None
        entry = MethodEntry(name=name or " ".join(words), args=tuple(words), trials=n, line=item.start_mark.line + 1,
                            params=params)
        if any(e.name == entry.name or e.ident == entry.ident for e in out):
            raise ctx.err(item, "methods", f"{entry.name!r} is listed twice")
        out.append(entry)
    return out


def _sim(ctx, node, where) -> SimSpec:
    from gevi_cli.simulate.presets import PRESET_NAMES, parse_resolution

    s = ctx.mapping(node, where, SIM_KEYS)
    preset = ctx.scalar(s, "preset", where, str)
    if preset not in PRESET_NAMES:
        raise ctx.err(s["preset"][1] if "preset" in s else node, f"{where}.preset",
                      f"unknown preset {preset!r}; choose one of {', '.join(PRESET_NAMES)}")
    res = ctx.scalar(s, "resolution", where, str)
    try:
        res = parse_resolution(res)
    except GeviError as exc:
        raise ctx.err(s["resolution"][1], f"{where}.resolution", exc.message) from None
    fmt = ctx.scalar(s, "format", where, str, "euroc",
                     lambda v: None if v in ("euroc", "kitti") else "must be euroc or kitti")
    imu = []
    for key in ("imu_rate", "gyro_noise", "gyro_walk", "acc_noise", "acc_walk"):
        v = ctx.scalar(s, key, where, float, None, lambda v: None if v >= 0 else "must not be negative")
        if v is not None:
            imu.append((key, v))
    if ctx.scalar(s, "no_imu_noise", where, bool, False):
        imu.append(("no_imu_noise", True))
    return SimSpec(preset=preset, seed=ctx.scalar(s, "seed", where, int, 0),
                   duration_s=ctx.scalar(s, "duration", where, float, None, _positive),
                   rate_hz=ctx.scalar(s, "rate", where, float, None, _positive), resolution=res,
                   baseline_m=ctx.scalar(s, "baseline", where, float, None, _positive), fmt=fmt, imu=tuple(imu),
                   distortion=ctx.scalar(s, "distortion", where, bool, True),
                   image_noise=ctx.scalar(s, "image_noise", where, bool, True),
                   supersample=ctx.scalar(s, "supersample", where, int, 2,
                                          lambda v: None if 1 <= v <= 8 else "must be 1..8"),
                   a_max=ctx.scalar(s, "a_max", where, float, None, _positive),
                   moving_start=ctx.scalar(s, "moving_start", where, bool, False),
                   disparity_shift_px=ctx.scalar(s, "disparity_shift", where, float, 0.0))


def _entry_name(ctx, mapping, item, section: str) -> str:
    """The required ``name:`` of an entry of ``section`` (sequences / baselines)."""
    name = ctx.scalar(mapping, "name", f"{section}[]", str)
    if not name:
        raise ctx.err(item, f"{section}[].name", "missing")
    return name


def _known_names(ctx, node, where: str, known: set, not_a_list: str, unknown) -> tuple:
    """A list of names each in ``known``; ``unknown(name)`` words the error for the first one that is not."""
    names = _value(node)
    if not isinstance(names, list) or not all(isinstance(x, str) for x in names):
        raise ctx.err(node, where, not_a_list)
    bad = [x for x in names if x not in known]
    if bad:
        raise ctx.err(node, where, unknown(bad[0]))
    return tuple(names)


def _sequences(ctx, node, cfg: BatchConfig) -> list:
    out = []
    method_names = {m.name for m in cfg.methods}
    for item in _seq_list(ctx, node, "sequences"):
        s = ctx.mapping(item, "sequences[]", SEQ_KEYS)
        name = _entry_name(ctx, s, item, "sequences")
        where = f"sequences.{name}"
        if slug(name) != name:
            raise ctx.err(s["name"][1], where, "use letters, digits and . _ + - only (it names folders)")
        if any(e.name == name for e in out):
            raise ctx.err(s["name"][1], where, "listed twice")
        if ("path" in s) == ("simulate" in s):
            raise ctx.err(item, where, "give exactly one of path: (a dataset) or simulate: (a render)")
        optional = ctx.scalar(s, "optional", where, bool, False)
        methods = None
        if "methods" in s:
            methods = _known_names(
                ctx, s["methods"][1], f"{where}.methods", method_names, "expected a list of method names",
                lambda m: f"unknown method {m!r}; the methods: are {', '.join(sorted(method_names))}")
        skip = ""
        files = {}
        for key in ("path", "gt", "calib", "imu_calib"):
            v = ctx.scalar(s, key, where, str)
            if v is None:
                continue
            p = cfg.resolve(v)
            if not p.exists():
                if optional:
                    skip = skip or f"{p} is absent"
                else:
                    raise ctx.err(s[key][1], f"{where}.{key}", f"{p}: no such file or folder")
            files[key] = str(p)
        sim = _sim(ctx, s["simulate"][1], f"{where}.simulate") if "simulate" in s else None
        out.append(SequenceEntry(
            name=name, line=item.start_mark.line + 1, path=files.get("path"), sim=sim, inputs=RunInputs(
                gt=files.get("gt"), calib=files.get("calib"), imu_calib=files.get("imu_calib"),
                kind=ctx.scalar(s, "kind", where, str), cameras=ctx.scalar(s, "cameras", where, str),
                topics=ctx.scalar(s, "topics", where, str),
                start=ctx.scalar(s, "start", where, int, 0, lambda v: None if v >= 0 else "must not be negative"),
                max_frames=ctx.scalar(s, "max_frames", where, int, None, _positive),
                stride=ctx.scalar(s, "stride", where, int, 1, lambda v: None if v >= 1 else "must be at least 1")),
            methods=methods, optional=optional,
            seed_per_trial=ctx.scalar(s, "seed_per_trial", where, bool, False), skip_reason=skip))
        if out[-1].seed_per_trial and sim is None:
            raise ctx.err(s["seed_per_trial"][1], f"{where}.seed_per_trial", "only for simulate: sequences")
    return out


def _baselines(ctx, node, cfg: BatchConfig) -> list:
    import numpy as np

    out = []
    seq_names = {s.name for s in cfg.sequences}
    for item in _seq_list(ctx, node, "baselines"):
        b = ctx.mapping(item, "baselines[]", BASELINE_KEYS)
        name = _entry_name(ctx, b, item, "baselines")
        where = f"baselines.{name}"
        path = ctx.scalar(b, "path", where, str)
        if not path or not ("{sequence}" in path or ("{stride}" in path and "sequences" in b)):
            raise ctx.err(b["path"][1] if "path" in b else item, f"{where}.path",
                          "expected a path template holding {sequence}, e.g. DIR/{sequence}/orbslam3_stereo "
                          "({stride} with a sequences: list)")
        fmt = ctx.scalar(b, "format", where, str, None,
                         lambda v: None if v in FORMATS else f"unknown format; choose one of {', '.join(FORMATS)}")
        if fmt is None:
            raise ctx.err(item, f"{where}.format", f"missing; declare the file format ({', '.join(FORMATS)})")
        frame = ctx.scalar(b, "frame", where, str, None,
                           lambda v: None if v in ("body", "cam0") else "must be body or cam0")
        if frame is None:
            raise ctx.err(item, f"{where}.frame", "missing; declare the sensor frame of the poses (body or cam0)")
        t_node = b.get("T_B_C0", (None, None))[1]
        T = _value(t_node) if t_node is not None else ("sequence" if frame == "cam0" else "identity")
        if isinstance(T, list):
            try:
                arr = np.asarray(T, dtype=float)  # 4 rows of 4, or 16 numbers
            except ValueError:
                raise ctx.err(t_node, f"{where}.T_B_C0", "expected a 4x4 matrix of numbers") from None
            if arr.size != 16:
                raise ctx.err(t_node, f"{where}.T_B_C0", f"expected a 4x4 matrix, got {arr.size} numbers")
            T = tuple(map(float, arr.reshape(-1)))
        elif T not in ("sequence", "identity"):
            p = cfg.resolve(str(T))
            if not p.is_file():
                raise ctx.err(t_node, f"{where}.T_B_C0", f"{p}: no such file (or say sequence / identity / a 4x4 list)")
            from gevi_cli.evaluation.inputs import load_T_B_C0

            try:
                load_T_B_C0(p)
            except GeviError as exc:
                raise ctx.err(t_node, f"{where}.T_B_C0", exc.one_line()) from None
            T = str(p)
        seqs = None
        if "sequences" in b:
            what = "expected a list of names from sequences:"
            seqs = _known_names(ctx, b["sequences"][1], f"{where}.sequences", seq_names, what, lambda _: what)
        optional = ctx.scalar(b, "optional", where, bool, False)
        stamps = ctx.scalar(b, "stamps", where, str, None,
                            lambda v: None if v == "sequence" else "must be sequence (or absent: the file's own)")
        if stamps and fmt != "kitti":
            raise ctx.err(b["stamps"][1], f"{where}.stamps", "only for format: kitti (rows without times)")
        template = path
        prefix = template.split("{")[0]  # the folder holding the first placeholder
        root_part = cfg.resolve(prefix if not prefix or prefix.endswith("/") else str(Path(prefix).parent))
        skip = ""
        if not root_part.exists():
            if not optional:
                raise ctx.err(b["path"][1], f"{where}.path", f"{root_part}: no such folder")
            skip = f"{root_part} is absent"
        out.append(BaselineEntry(name=name, line=item.start_mark.line + 1, path=template,
                                 files=_files(ctx, b, where), fmt=fmt, frame=frame, T_B_C0=T, stamps=stamps,
                                 sequences=seqs, optional=optional, skip_reason=skip))
    return out


def _files(ctx, b: dict, where: str) -> tuple:
    """``file:`` as a tuple of names: one, or a list (one per run of the system)."""
    if "file" not in b:
        return ()
    node = b["file"][1]
    value = _value(node)
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not names or not all(isinstance(x, str) and x for x in names):
        raise ctx.err(node, f"{where}.file", "expected a file name or a non-empty list of them (one per run)")
    if len(set(names)) != len(names):
        raise ctx.err(node, f"{where}.file", "lists a file twice")
    return tuple(names)
