"""What a service refuses, in a racer's words: the one type views and commands catch."""

from __future__ import annotations

from collections.abc import Mapping

WHOLE = "__all__"  # the key of what concerns no one input (Django's forms name it so)


class Refused(Exception):
    """The service did not do what it was asked; ``errors`` maps each input at fault to what is
    wrong with it, or ``WHOLE`` to what concerns the request as a whole. Every service's refusal
    is one (``configuration.Invalid``, ``ImportRefused``, ``SubmissionRefused``, ...), so a view
    or a command catches this type and shows what it says."""

    def __init__(self, errors: str | Mapping[str, str]) -> None:
        self.errors = {WHOLE: errors} if isinstance(errors, str) else dict(errors)
        super().__init__(
            "; ".join(
                message if name == WHOLE else f"{name}: {message}"
                for name, message in self.errors.items()
            )
        )

    def told(self, what: str) -> str:
        """The refusal after ``what`` was refused ("The model was not imported"), as a command
        prints it: on the same line when it is one sentence, else one line per input."""
        if list(self.errors) == [WHOLE]:
            return f"{what}: {self.errors[WHOLE]}"
        lines = "\n".join(
            f"  {message}" if name == WHOLE else f"  {name}: {message}"
            for name, message in self.errors.items()
        )
        return f"{what}:\n{lines}"
