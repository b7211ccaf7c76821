"""What a check finds: errors refuse the run, warnings and notes go into the report."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from kitegully import InputError

LEVELS = ("error", "warning", "note")


@dataclass(frozen=True)
class Finding:
    """One finding of the input checks.

    Attributes
    ----------
    level : str
        ``error`` (the run is refused), ``warning`` (the run goes on, the report says why
        it may suffer) or ``note`` (a fact worth knowing).
    source : str
        The file or config key the finding is about.
    message : str
        One sentence, without the source.
    """

    level: str
    source: str
    message: str

    @property
    def line(self) -> str:
        """The one line shown to the user: ``<source>: <message>``."""
        return f"{self.source}: {self.message}"


@dataclass
class Findings:
    """Findings collected in order, plus facts about the inputs (counts, extents)."""

    items: list[Finding] = field(default_factory=list)
    facts: dict = field(default_factory=dict)

    def add(self, level: str, source: str, message: str) -> None:
        """Append a finding; ``level`` must be one of :data:`LEVELS` (else ValueError).

        Parameters
        ----------
        level : str
            ``error``, ``warning`` or ``note``.
        source : str
            The file or config key the finding is about; stored as ``str(source)``.
        message : str
            One sentence, without the source.
        """
        if level not in LEVELS:
            raise ValueError(f"unknown finding level {level!r}")
        self.items.append(Finding(level, str(source), message))

    def error(self, source: str, message: str) -> None:
        """Add an error: the run is refused."""
        self.add("error", source, message)

    def warning(self, source: str, message: str) -> None:
        """Add a warning: the run goes on, the report says why it may suffer."""
        self.add("warning", source, message)

    def note(self, source: str, message: str) -> None:
        """Add a note: a fact worth knowing."""
        self.add("note", source, message)

    def of(self, level: str) -> list[Finding]:
        """The findings of one level, in the order they were added."""
        return [f for f in self.items if f.level == level]

    @property
    def errors(self) -> list[Finding]:
        """The error findings, in order."""
        return self.of("error")

    @property
    def ok(self) -> bool:
        """True when there is no error."""
        return not self.errors

    def as_dict(self) -> dict:
        """The report: verdict (``accepted``/``refused``), findings by level (each with its ``line``), facts."""
        return {
            "verdict": "accepted" if self.ok else "refused",
            "errors": [asdict(f) | {"line": f.line} for f in self.of("error")],
            "warnings": [asdict(f) | {"line": f.line} for f in self.of("warning")],
            "notes": [asdict(f) | {"line": f.line} for f in self.of("note")],
            "facts": self.facts,
        }

    def raise_for_errors(self) -> None:
        """Raise :class:`InputError` with the first error's line (and how many more there are)."""
        errs = self.errors
        if not errs:
            return
        more = f" ({len(errs) - 1} more problem(s) listed in the log)" if len(errs) > 1 else ""
        raise InputError(errs[0].line + more)
