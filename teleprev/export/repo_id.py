"""Dataset names (`--repo-id`) by the Hugging Face Hub's rules, checked before anything is written: the name
also chooses the default folder (datasets/out/<repo-id>), so a name the Hub would refuse could write outside
it ("../x") or point at the folder of every dataset ("")."""

from __future__ import annotations

import re

from teleprev.errors import ConfigError

MAX_LENGTH = 96  # of the namespace and of the name
_PART = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9_.-]*[A-Za-z0-9_])?")  # no '-' or '.' at either end


def check_repo_id(repo_id: str) -> str:
    """`repo_id` when it is `name` or `namespace/name` as the Hub accepts it, else a ConfigError saying why."""
    why = _problem(repo_id)
    if why:
        raise ConfigError(f"--repo-id {repo_id!r}: {why} (a dataset name is 'name' or 'namespace/name', "
                          "e.g. lab/pick_place)")
    return repo_id


def _problem(repo_id: str) -> str:
    if not repo_id:
        return "empty"
    parts = repo_id.split("/")
    if len(parts) > 2:
        return "more than one '/'"
    for part in parts:
        if len(part) > MAX_LENGTH:
            return f"a part longer than {MAX_LENGTH} characters"
        if not _PART.fullmatch(part):
            return ("letters, digits, '-', '_' and '.' only, neither '-' nor '.' at the start or end of either "
                    f"part ({part!r})")
    if "--" in repo_id or ".." in repo_id:
        return "'--' and '..' are not allowed"
    if repo_id.endswith(".git"):
        return "a name may not end with '.git'"
    return ""
