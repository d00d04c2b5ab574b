"""The hub's access-control rules: what each role of a range may put on and take from the bus.

The hub (the bridge's session) checks every message a client sends it (``ingress``) and
every message it forwards to a client (``egress``) against these rules; anything not
allowed is dropped (``default_permission: deny``). A client is known by the common name
of the certificate it showed in the mutual-TLS handshake, so a role cannot claim another
role's name: an autonomy whose certificate says ``rogue`` may put ``command/rogue`` but not
``command/autonomy``. The hub's own puts are local and not checked.

A client that may put is also told of the hub's subscribers (egress ``declare_subscriber``): a
Zenoh publisher sends nothing to a key no one has declared interest in. A rule applies to a
declaration only if it includes the subscriber's whole key expression (the bridge's
``command/*``, the logger's ``rapt/<v>/**``), so this rule covers the vehicle's keys; being told
of a subscriber moves no data, and what the client may put is still only its ``put`` keys.
"""

from __future__ import annotations

from collections.abc import Iterable

from bridge import keys

__all__ = ["HUB_ROLE", "OTHER_ROLES", "role_permissions", "access_rules", "permissions_table"]

#: The role whose session is the hub (it listens; its own puts are not checked).
HUB_ROLE = "bridge"
#: The roles besides the hub and the autonomies, each connecting as a client.
OTHER_ROLES = (keys.WATCHDOG_SOURCE, "logger", "operator")


def _vehicle_keys(vehicle: str) -> dict[str, str]:
    return {
        "telemetry": f"{keys.PREFIX}/{vehicle}/mavlink/**",
        "virtual": f"{keys.PREFIX}/{vehicle}/virtual/**",
        "meta": f"{keys.PREFIX}/{vehicle}/meta/**",
        "map": f"{keys.PREFIX}/{vehicle}/map/**",
        "active": keys.active(vehicle),
        "commands": keys.command(vehicle, "*"),
        "status": keys.status(vehicle, "*"),
        "alive": keys.alive(vehicle, "*"),
        "everything": keys.everything(vehicle),
    }


def role_permissions(vehicle: str, role: str, *, autonomy: bool = False) -> dict[str, list[str]]:
    """What ``role`` may do on ``vehicle``'s bus: ``{"put": keys, "subscribe": keys, "alive": keys}``.

    ``alive`` lists the liveliness tokens it may declare; an ``autonomy`` role is one named
    autonomy (its set-points on ``command/<role>``). The hub role gets nothing: it is not
    a client. This is also the docs' table of what each role may do.
    """
    k = _vehicle_keys(vehicle)
    own = [keys.status(vehicle, role)]
    if role == HUB_ROLE:
        return {"put": [], "subscribe": [], "alive": []}
    if autonomy:
        # and the scenario's map for the log (planner.fly.scenario_map; drawn, never acted on)
        return {
            "put": [keys.command(vehicle, role), *own, keys.map_document(vehicle, "scenario")],
            "subscribe": [k["telemetry"], k["virtual"], k["meta"], k["active"]],
            "alive": [keys.alive(vehicle, role)],
        }
    if role == "logger":
        # the logger's own counters (status/logger) are only logged; it puts no command and no control
        return {"put": own, "subscribe": [k["everything"]], "alive": [keys.alive(vehicle, role)]}
    if role in (keys.WATCHDOG_SOURCE, "operator"):
        return {
            "put": [k["active"], keys.command(vehicle, role), *own],
            "subscribe": [k["telemetry"], k["virtual"], k["meta"], k["active"], k["commands"], k["status"]],
            "alive": [keys.alive(vehicle, role)],
        }
    raise ValueError(f"role: {role!r} is not one of {HUB_ROLE}, {', '.join(OTHER_ROLES)} or an autonomy")


def _rule(rule_id: str, flow: str, messages: list[str], key_exprs: list[str]) -> dict:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": key_exprs}


def access_rules(vehicle: str, autonomies: Iterable[str] = (keys.DEFAULT_ACTIVE,)) -> dict:
    """The ``access_control`` block of the hub's Zenoh config for ``vehicle`` and its named ``autonomies``.

    Default deny; one subject per client role, matched by its certificate's common name.
    """
    vehicle = keys.everything(vehicle).split("/")[1]  # checks the name is one key chunk
    autonomies = list(autonomies)
    rules: list[dict] = []
    subjects: list[dict] = []
    policies: list[dict] = []
    alive_all = _vehicle_keys(vehicle)["alive"]
    for role, is_autonomy in [(a, True) for a in autonomies] + [(r, False) for r in OTHER_ROLES]:
        allowed = role_permissions(vehicle, role, autonomy=is_autonomy)
        grants = [
            ("puts", "ingress", ["put"], allowed["put"]),
            # a rule must include a subscriber's whole key expression (the bridge's command/*, the logger's
            # rapt/<v>/**), so every subscriber of the vehicle is told of; being told moves no data
            (
                "hears who takes its puts",
                "egress",
                ["declare_subscriber"],
                [keys.everything(vehicle)] if allowed["put"] else [],
            ),
            ("subscribes", "ingress", ["declare_subscriber"], allowed["subscribe"]),
            ("receives", "egress", ["put"], allowed["subscribe"]),
            ("is alive", "ingress", ["liveliness_token"], allowed["alive"]),
            ("watches who is alive", "ingress", ["declare_liveliness_subscriber", "liveliness_query"], [alive_all]),
            ("sees who is alive", "egress", ["liveliness_token"], [alive_all]),
        ]
        ids = [f"{role} {suffix}" for suffix, *_ in grants]
        rules += [_rule(i, flow, messages, key_exprs) for i, (_, flow, messages, key_exprs) in zip(ids, grants)]
        subjects.append({"id": role, "cert_common_names": [role]})
        policies.append({"id": f"{role} policy", "rules": ids, "subjects": [role]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def permissions_table(vehicle: str, autonomies: Iterable[str] = (keys.DEFAULT_ACTIVE,)) -> str:
    """What each client role may do, as the Markdown table of the range administrator's docs page."""
    rows = ["| role | may put | may subscribe to | liveliness token |", "|---|---|---|---|"]
    for role, is_autonomy in [(a, True) for a in autonomies] + [(r, False) for r in OTHER_ROLES]:
        allowed = role_permissions(vehicle, role, autonomy=is_autonomy)
        cells = [", ".join(f"`{k}`" for k in allowed[what]) for what in ("put", "subscribe", "alive")]
        rows.append(f"| {role} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"
