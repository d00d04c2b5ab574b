"""Which role a key's samples came from on a secure bus, read off the hub's access-control rules.

On the range's secure bus (:mod:`bridge.range_keys`) the hub lets a client put a key only if a
rule allows that client's role (its certificate's common name) to; the hub's own puts (the
bridge, and what shares its session) are not checked. So the roles whose rules allow puts on a
key are the only ones its samples can have come from, and a key no client may put came from the
hub. The logger records this per channel (:class:`bridge.logger.McapLogger`'s ``roles``).
"""

from __future__ import annotations

from collections.abc import Mapping

import zenoh

__all__ = ["HUB", "put_roles", "ChannelRoles"]

#: The role of whatever no client may put: the hub's own session (the bridge role).
HUB = "bridge"


def put_roles(access_control: Mapping) -> dict[str, list[str]]:
    """``{key expression: [roles allowed to put it]}`` from a Zenoh ``access_control`` block.

    Only ``allow`` rules on ``put`` (or ``liveliness_token``: the logger records a token's changes
    on its key) in the ingress flow count (a rule without flows applies to both); a subject's
    roles are its ``cert_common_names``.
    """
    rules = {rule["id"]: rule for rule in access_control.get("rules", [])}
    subjects = {subject["id"]: subject for subject in access_control.get("subjects", [])}
    out: dict[str, list[str]] = {}
    for policy in access_control.get("policies", []):
        names = [cn for sid in policy.get("subjects", []) for cn in subjects.get(sid, {}).get("cert_common_names", [])]
        for rid in policy.get("rules", []):
            rule = rules.get(rid, {})
            messages = rule.get("messages", [])
            if rule.get("permission") != "allow" or not {"put", "liveliness_token"} & set(messages):
                continue
            if "ingress" not in rule.get("flows", ["ingress", "egress"]):
                continue
            for key_expr in rule.get("key_exprs", []):
                roles = out.setdefault(key_expr, [])
                roles += [name for name in names if name not in roles]
    return out


class ChannelRoles:
    """The role(s) a concrete key's samples came from: ``"autonomy"``, ``"operator,watchdog"``, ``"bridge"``."""

    def __init__(self, by_key_expr: Mapping[str, list[str]]):
        self.by_key_expr = {k: sorted(v) for k, v in by_key_expr.items()}
        self._exprs = [(zenoh.KeyExpr(k), v) for k, v in self.by_key_expr.items()]
        self._cache: dict[str, str] = {}

    def __call__(self, key: str) -> str:
        role = self._cache.get(key)
        if role is None:
            try:
                concrete = zenoh.KeyExpr(key)
            except zenoh.ZError:
                concrete = None
            roles = sorted(
                {r for expr, rs in self._exprs if concrete is not None and expr.includes(concrete) for r in rs}
            )
            role = self._cache[key] = ",".join(roles) or HUB
        return role
