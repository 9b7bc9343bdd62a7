"""The UI's classes stay small (issue 34, the UI by composition): no class of ``web``
has more methods than :data:`MOST_METHODS`, a mixin's methods counted with every class
that inherits them. Lower the bound as components leave ``TeleopApp`` and ``TeleopUI``;
never raise it."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import web

#: The largest classes' methods now: ``web.app.robots.Robots`` 19; ``TeleopApp`` 6, no
#: mixin (15 with the scenes' and the tick's mixins before they became the components
#: ``app.scenes`` and ``app.ticker``; 100 with 12 mixins before the recording, the way
#: home, the collision scene and the input devices left it as components; 76
#: before the devices' actions went to :class:`web.app.devices.InputDevices`, the
#: obstacles' and collision settings' to
#: :class:`web.app.collisions.CollisionScene`, the loops and their settings to
#: :class:`web.app.robots.Robots`, the placed constraints to
#: :class:`web.app.editing.ConstraintEditing`, the console to
#: :class:`web.app.console.Console`, what the view reads to :class:`web.app.view.View`);
#: ``TeleopUI`` 13, no mixin (84 with 10
#: mixins before the live plots, the status, device, Teleop, Settings and collision
#: settings panels, the placed items' panels and markers, the pairs' highlights, the
#: scene view and the port arrows became components it holds).
#: The closing target is 30.
MOST_METHODS = 19

#: Functions, properties and static or class methods are methods here.
METHOD_KINDS = (property, staticmethod, classmethod)


def methods(cls: type) -> set[str]:
    """The names of the methods ``cls`` has from the classes of ``web`` it is or derives
    from (its mixins' included)."""
    names = set()
    for klass in cls.__mro__:
        if klass.__module__.split(".")[0] != "web":
            continue
        names.update(name for name, value in vars(klass).items()
                     if inspect.isfunction(value) or isinstance(value, METHOD_KINDS))
    return names


def web_classes() -> dict[str, type]:
    """Every class defined in a module of ``web`` (``web.__main__`` starts a server when
    imported, and defines none)."""
    classes = {}
    for module_info in pkgutil.walk_packages(web.__path__, "web."):
        if module_info.name.endswith("__main__"):
            continue
        module = importlib.import_module(module_info.name)
        classes.update({f"{module.__name__}.{name}": value for name, value in vars(module).items()
                        if inspect.isclass(value) and value.__module__ == module.__name__})
    return classes


def test_the_counter_counts_a_mixins_methods_with_its_class() -> None:
    """A reference written here: two methods of a mixin and one of the class (a property
    among them), and nothing of a class outside ``web``."""

    class Mixin:
        def first(self) -> None: ...

        @property
        def second(self) -> int:
            return 2

    class Front(Mixin, dict):
        def third(self) -> None: ...

    Mixin.__module__ = Front.__module__ = "web.example"
    assert methods(Front) == {"first", "second", "third"}


def test_no_web_class_has_more_methods_than_the_bound() -> None:
    classes = web_classes()
    assert "web.app.core.TeleopApp" in classes and "web.ui.core.TeleopUI" in classes
    sizes = {name: len(methods(cls)) for name, cls in classes.items()}
    largest = max(sizes, key=sizes.__getitem__)
    assert sizes[largest] <= MOST_METHODS, f"{largest} has {sizes[largest]} methods"
