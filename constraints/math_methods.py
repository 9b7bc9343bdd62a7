"""Which methods make up a constraint type's math (docs/design.md section 3), for the readers
that repeat a registered type's math for its subclasses: the compiled CJM step's forms
(``controllers/cjm/compiled_forms.py``), the analytical CJM's affine forms
(``controllers/cjm/affine_forms.py``) and the loop's batched measures
(``teleop/loop/batched_evaluation.py``).

Such a reader may take a subclass as its registered base only when the subclass computes
what the base computes: it overrides none of :data:`MATH_METHODS` (nor the reader's own
``also``). A subclass with its own math is evaluated by it, at Python's cost.
"""

from __future__ import annotations

#: the evaluation of section 3 and the built-in types' helpers their evaluation calls (a
#: hole's ``evaluate_local``, a plane's ``signed_distance``)
MATH_METHODS = ("point", "directions", "free_directions", "error", "feed_forward", "evaluate",
                "evaluate_local", "signed_distance")


def keeps_math(constraint_type: type, base: type, also: tuple[str, ...] = ()) -> bool:
    """Whether ``constraint_type`` has ``base``'s :data:`MATH_METHODS` and ``also``
    (the same objects: none overridden on the way down)."""
    return all(getattr(constraint_type, name, None) is getattr(base, name, None)
               for name in (*MATH_METHODS, *also))
