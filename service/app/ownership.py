"""Who may see a session or a build job: the key that created it, or an ``admin`` key.

A resource created through the API records its owner, the sha256 digest of the API key that
created it (the form ``QUADLOC_API_KEYS`` holds: never the key itself). Another key is
answered as if the resource did not exist (404 ``session-not-found`` / ``not-found``, the same
answer as for an unknown id, so ids of other keys cannot be probed); a key with the ``admin``
scope sees, follows and deletes every resource. A server without keys (loopback only) has one
caller, who sees everything. Rules: docs/api.md, "Ownership and quotas".
"""

from __future__ import annotations

from dataclasses import dataclass

from quadloc.service.settings import ApiKey

__all__ = ["INTERNAL", "Caller"]


@dataclass(frozen=True)
class Caller:
    """The caller of a use case: ``owner`` (its key's sha256, None without keys) and whether it
    sees every owner's resources (``admin``)."""

    owner: str | None
    admin: bool = False

    @classmethod
    def of(cls, key: ApiKey | None) -> Caller:
        """The caller authenticated with ``key`` (None: the server has no keys; it sees
        everything)."""
        if key is None:
            return cls(None, admin=True)
        return cls(key.sha256, admin=key.allows("admin"))

    def may_access(self, owner: str | None) -> bool:
        """True when this caller may see a resource created by ``owner``."""
        return self.admin or (self.owner is not None and self.owner == owner)


#: The process itself (the CLI, tests, maintenance): no owner, sees everything.
INTERNAL = Caller(None, admin=True)
