"""Plugin discovery through entry points, with broken-plugin isolation and id clashes."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import pluggy

from . import hookspecs
from .algorithm import Algorithm
from .errors import PluginError, UsageError

log = logging.getLogger(__name__)
ENTRY_POINT_GROUP = "toolbox.plugins"


@dataclass
class BrokenPlugin:
    name: str
    distribution: str
    version: str
    reason: str


@dataclass
class Registry:
    """What discovery found: algorithms by id, broken plugins, clashing ids, style dirs."""

    algorithms: dict[str, Algorithm] = field(default_factory=dict)
    broken: list[BrokenPlugin] = field(default_factory=list)
    clashes: dict[str, list[str]] = field(default_factory=dict)
    style_dirs: list[Path] = field(default_factory=list)
    plugins: dict[str, tuple[str, str]] = field(default_factory=dict)  # name -> (dist, version)
    #: the (name, value) of each entry point when they were given (tests), so that worker
    #: processes of a survey run rediscover the same plugins; None: the installed ones
    entry_points: list[tuple[str, str]] | None = None

    def get(self, algorithm_id: str) -> Algorithm:
        if algorithm_id in self.clashes:
            owners = " and ".join(self.clashes[algorithm_id])
            raise PluginError(
                f"algorithm id {algorithm_id!r} is claimed by two plugins ({owners}); "
                "uninstall or rename one of them"
            )
        try:
            return self.algorithms[algorithm_id]
        except KeyError:
            import difflib

            hint = difflib.get_close_matches(algorithm_id, list(self.algorithms), n=1, cutoff=0.5)
            extra = f"; did you mean {hint[0]!r}?" if hint else "; 'toolbox list' shows them all"
            raise UsageError(f"unknown algorithm {algorithm_id!r}{extra}") from None


def _host_style_dir() -> Path:
    import toolbox_styles  # the repository's styles/ folder, installed as a package

    return Path(toolbox_styles.__file__).parent


def discover(entry_points=None) -> Registry:
    """Load every plugin of the ``toolbox.plugins`` group and collect its algorithms.

    ``entry_points`` may be given (tests); it defaults to the installed ones.
    """
    reg = Registry()
    pm = pluggy.PluginManager(hookspecs.PROJECT)
    pm.add_hookspecs(hookspecs)
    if entry_points is None:
        entry_points = metadata.entry_points(group=ENTRY_POINT_GROUP)
    else:
        entry_points = list(entry_points)
        reg.entry_points = [(ep.name, ep.value) for ep in entry_points]
    owners: dict[str, str] = {}
    plugin_dirs: list[Path] = []
    for ep in sorted(entry_points, key=lambda e: e.name):
        dist = getattr(ep, "dist", None)
        dist_name = dist.metadata["Name"] if dist is not None else "?"
        version = dist.version if dist is not None else "?"
        reg.plugins[ep.name] = (dist_name, version)
        try:
            obj = ep.load()
            pm.register(obj, name=ep.name)
        except BaseException as exc:  # a broken third-party plugin (even sys.exit) must not take the host down
            _reraise_if_signalled(exc)
            reg.broken.append(BrokenPlugin(ep.name, dist_name, version, f"failed to load: {_one_line(exc)}"))
            log.debug("plugin %s failed to load", ep.name, exc_info=True)
            continue
        try:
            algs = _call_one(pm, "toolbox_algorithms", obj)
            dirs = _call_one(pm, "toolbox_style_dirs", obj)
            algs = list(algs or [])
            for a in algs:
                if not isinstance(a, Algorithm):
                    raise TypeError(f"toolbox_algorithms returned {type(a).__name__}, not toolbox.Algorithm")
        except BaseException as exc:
            _reraise_if_signalled(exc)
            pm.unregister(obj)
            reg.broken.append(BrokenPlugin(ep.name, dist_name, version, f"hook failed: {_one_line(exc)}"))
            log.debug("plugin %s failed in a hook", ep.name, exc_info=True)
            continue
        plugin_dirs.extend(Path(d) for d in (dirs or []))
        for a in algs:
            a.plugin, a.distribution, a.version = ep.name, dist_name, version
            if a.id in owners or a.id in reg.clashes:
                first = owners.pop(a.id, None)
                reg.algorithms.pop(a.id, None)
                names = reg.clashes.setdefault(a.id, [first] if first else [])
                names.append(f"{ep.name} ({dist_name})")
                continue
            owners[a.id] = f"{ep.name} ({dist_name})"
            reg.algorithms[a.id] = a
    reg.style_dirs = plugin_dirs + [_host_style_dir()]
    return reg


def rediscover(entry_points: list[tuple[str, str]] | None) -> "Registry":
    """The registry a worker process uses: the installed plugins, or the given entry points."""
    if entry_points is None:
        return registry()
    return discover([metadata.EntryPoint(name=n, value=v, group=ENTRY_POINT_GROUP) for n, v in entry_points])


def _call_one(pm: pluggy.PluginManager, hook_name: str, plugin) -> object:
    """Call one plugin's implementation of a hook (so one plugin's failure stays its own)."""
    hook = getattr(pm.hook, hook_name)
    for impl in hook.get_hookimpls():
        if impl.plugin is plugin:
            return impl.function()
    return None


def _reraise_if_signalled(exc: BaseException) -> None:
    """Ctrl-C and SIGTERM stop the host; a KeyboardInterrupt a plugin raises itself does not
    (told apart by the host's signal handler; without it, every KeyboardInterrupt is Ctrl-C)."""
    from . import signals

    if isinstance(exc, signals.Terminated) or signals.received() is not None:
        raise exc
    if isinstance(exc, KeyboardInterrupt) and not signals.installed():
        raise exc


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        return f"called sys.exit({exc.code!r})"
    text = f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())[:300]


_REGISTRY: Registry | None = None


def registry(refresh: bool = False) -> Registry:
    """The process-wide registry, discovered once."""
    global _REGISTRY
    if _REGISTRY is None or refresh:
        _REGISTRY = discover()
    return _REGISTRY
