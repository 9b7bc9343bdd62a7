"""JSON text read with one-line errors (session lines, scene files)."""

from __future__ import annotations

import json


def parse_json(text: str, where: str, error: type[ValueError] = ValueError) -> object:
    """The JSON value of ``text``; else ``error`` (a ``ValueError``) that starts with
    ``where``: not JSON (with the position), nested too deeply, or not readable (an
    integer of more than 4300 digits)."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as problem:
        position = (f"column {problem.colno}" if problem.lineno == 1
                    else f"line {problem.lineno} column {problem.colno}")
        raise error(f"{where}: not JSON ({problem.msg}, {position})") from None
    except RecursionError:
        raise error(f"{where}: JSON nested too deeply") from None
    except ValueError as problem:
        raise error(f"{where}: not readable JSON ({problem})") from None
