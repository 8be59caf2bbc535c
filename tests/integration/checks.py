"""Named checks for the integration tests' log readers: each printed, all remembered."""
import sys


class Checks:
    """check(cond, what) prints '# what' or '# FAILED: what' and remembers a failure in .ok."""

    def __init__(self):
        self.ok = True

    def __call__(self, cond, what):
        print(("# " if cond else "# FAILED: ") + what, file=sys.stderr)
        self.ok = self.ok and bool(cond)
        return cond
