"""Markdown tables for the benchmark reports."""
from typing import Any, Sequence

__all__ = []


def markdown_table(headers: Sequence[str],
                   rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured Markdown table, numbers right-aligned; a cell's
    ``|`` is escaped and its line breaks become spaces, so any text (an
    error message, a tuning key) stays in its cell."""
    cells = [[_cell(c) for c in row] for row in rows]
    widths = [max([len(h)] + [len(r[i]) for r in cells])
              for i, h in enumerate(headers)]
    numeric = [bool(cells) and all(_is_number(r[i]) for r in cells)
               for i in range(len(headers))]

    def line(values):
        return '| ' + ' | '.join(
            v.rjust(w) if num else v.ljust(w)
            for v, w, num in zip(values, widths, numeric)) + ' |'

    rule = '|' + '|'.join(('-' * (w + 1) + ':') if num else '-' * (w + 2)
                          for w, num in zip(widths, numeric)) + '|'
    return '\n'.join([line(headers), rule] + [line(r) for r in cells])


def _cell(value: Any) -> str:
    return ' '.join(str(value).splitlines()).replace('|', '\\|')


def _is_number(text: str) -> bool:
    """``'12'``, ``'1.5 ± 0.1'``, ``'5.0%'`` and ``'-'`` (none) align as
    numbers."""
    try:
        float(text.split(' ')[0].rstrip('%'))
    except ValueError:
        return text == '-'
    return True
