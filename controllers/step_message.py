"""A step's message, worded when it is read (docs/design.md sections 8.3 and 16).

A step's status is decided as it runs; its message (why the status is not ``ok``, in
words: the joints at a limit, the damping, the residual) is only text for whoever reads
it. The closed loop carries the message of every period to its records, the supervisor
adds its own words, and most periods nobody reads any of it: a :class:`StepMessage` keeps
the function that words it and calls it on the first read of :attr:`StepMessage.text`,
once, so the text is the one the step would have written at once.
"""

from __future__ import annotations

from typing import Callable


class StepMessage:
    """The text of a step's message, worded on its first read.

    ``StepMessage(word)`` calls ``word()`` on the first read of :attr:`text` and keeps the
    result (``word`` must read only what does not change after the step: its report, the
    names); :meth:`worded` holds a text already written.
    """

    __slots__ = ("_word", "_text")

    def __init__(self, word: Callable[[], str]) -> None:
        self._word: Callable[[], str] | None = word
        self._text = ""

    @classmethod
    def worded(cls, text: str) -> StepMessage:
        """A message whose text is ``text`` (written already)."""
        message = cls.__new__(cls)
        message._word, message._text = None, text
        return message

    @property
    def text(self) -> str:
        """The message in words (worded now if this is the first read)."""
        word = self._word
        if word is not None:
            self._text, self._word = word(), None
        return self._text

    def __str__(self) -> str:
        return self.text

    def __repr__(self) -> str:
        return f"StepMessage({self.text!r})"


#: the message of a step that went as planned
NO_MESSAGE = StepMessage.worded("")
