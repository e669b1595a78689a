"""Commands through the API are checked against the protocol's vocabulary before they are queued."""

from __future__ import annotations

from tests.conftest import Tenant


def test_a_bad_command_is_a_422_naming_the_field_and_nothing_is_queued(api, tenant: Tenant):
    uav = tenant.create_asset("uav")
    url = f"/api/v1/assets/{uav['id']}/commands"
    cases = [
        ({"name": "teleport"}, "unknown command 'teleport'"),
        ({"name": "start_charging", "params": {"current_limit_ma": "lots"}}, "current_limit_ma"),
        (
            {"name": "upload_mission", "params": {"items": [{"command": 16, "lat": 123.0}]}},
            "items.0.lat",
        ),
        ({"name": "open", "params": {"fast": True}}, "fast"),
    ]
    for body, where in cases:
        r = api.post(url, headers=tenant.h("operator"), json=body)
        assert r.status_code == 422, r.text
        error = r.json()["error"]
        assert error["code"] == "invalid_command" and where in error["message"], error
    assert api.get(url, headers=tenant.h("viewer")).json() == []


def test_a_good_command_is_queued_with_its_params_as_sent(api, tenant: Tenant):
    base = tenant.create_asset("landing_base")
    r = api.post(
        f"/api/v1/assets/{base['id']}/commands",
        headers=tenant.h("operator"),
        json={"name": "start_charging", "params": {"current_limit_ma": 4000}},
    )
    assert r.status_code == 202, r.text
    assert r.json()["params"] == {"current_limit_ma": 4000} and r.json()["status"] == "queued"


def test_a_command_for_the_other_kind_of_asset_is_a_422_and_nothing_is_queued(api, tenant: Tenant):
    """Issue 48 finding 6: a base does not fly and a UAV has no panels."""
    uav, base = tenant.create_asset("uav"), tenant.create_asset("landing_base")
    wrong = {
        base["id"]: ["start_mission", "return_to_base", "upload_mission", "land", "abort"],
        uav["id"]: ["open", "close", "lift_up", "start_charging", "stop", "reset_faults"],
    }
    for asset_id, names in wrong.items():
        url = f"/api/v1/assets/{asset_id}/commands"
        kind = "landing_base" if asset_id == base["id"] else "uav"
        for name in names:
            item = {"command": 16, "lat": 47.39, "lon": 8.54, "alt": 20}
            params = {"items": [item]} if name == "upload_mission" else {}
            r = api.post(url, headers=tenant.h("operator"), json={"name": name, "params": params})
            assert r.status_code == 422, (name, r.text)
            error = r.json()["error"]
            assert error["code"] == "invalid_command", error
            assert error["message"].endswith(f"not a {kind}"), error
        assert api.get(url, headers=tenant.h("viewer")).json() == []
    # what both kinds answer is taken by either
    for asset_id in wrong:
        r = api.post(
            f"/api/v1/assets/{asset_id}/commands",
            headers=tenant.h("operator"),
            json={"name": "check_availability"},
        )
        assert r.status_code == 202, r.text
