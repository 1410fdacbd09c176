"""The plugin contract: pluggy hook specifications.

A plugin is a module (or object) that implements some of these hooks with
``@toolbox.hookimpl`` and is declared as an entry point in the group ``toolbox.plugins``::

    [project.entry-points."toolbox.plugins"]
    my_plugin = "my_package.plugin"

The host calls each plugin's hooks separately: a plugin that fails to import, raises in a hook
or returns something that is not what the contract says is reported as broken (``toolbox list``
shows it with the reason) and never takes down the host or other plugins.
"""

from __future__ import annotations

import pluggy

PROJECT = "toolbox"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def toolbox_algorithms():
    """Return the algorithms this plugin provides, as a list of :class:`toolbox.Algorithm`.

    Each algorithm declares a unique id (lower-case words joined by ``-``), a title, a
    description, the reference of the method it implements, typed parameters
    (:class:`toolbox.Parameter`: type, default, unit, range or choices, description), its inputs
    (:class:`toolbox.Input`: point cloud, raster, vector, photo set), its outputs
    (:class:`toolbox.Output`) and a ``run(inputs, params, ctx)`` function.

    Contract for ``run``:

    * it receives data already read by the host and parameters already validated, defaults
      included; it must not read or write files itself (the host does, atomically);
    * it returns a :class:`toolbox.Result` (or a dict ``{output name: data}``); an optional
      output may be left out;
    * bad data raises :class:`toolbox.DataError` with a one-line message naming the input and
      the fix; anything else it raises is reported as a failure of the algorithm;
    * it may call other algorithms through ``ctx.call(id, inputs, **params)``, never by
      importing another plugin's modules;
    * taichi kernels get their runtime through ``ctx.taichi()`` (initialised once, lazily).

    Keep the module that implements this hook cheap to import: import the algorithm's core
    inside ``run`` so that ``toolbox list`` stays fast.
    """


@hookspec
def toolbox_style_dirs():
    """Return directories (``str`` or ``pathlib.Path``) holding QGIS ``.qml`` styles.

    A vector layer named ``L`` is styled with ``L.qml``; a raster output declaring
    ``style="S"`` with ``S.qml``. Plugins' directories are searched before the host's own
    ``styles/``, so a plugin can ship styles for its own layers or restyle built-in ones.
    """
