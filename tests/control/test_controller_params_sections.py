"""control_loop_params / shipped_configuration read every section of the shipped parameter files:
the stages, the hybrid position/force control, load compensation and hand guiding."""
import numpy as np
import pytest

from cdpr_control.control.admittance_zones import check_in_workspace, force_limits, per_axis
from cdpr_control.control.params import control_loop_params, load_params_file, shipped_configuration
from cdpr_control.control.load_compensation import LoadCompensationStage
from cdpr_control.model.robot import load_robot


@pytest.mark.parametrize("name", ["ipanema3", "ipanema3_mini"])
def test_every_section_of_the_shipped_file_is_read(name):
    robot = load_robot(name)
    file = load_params_file(name)
    shipped = shipped_configuration(robot)
    assert shipped.dt == file["/**"]["control_period"]
    # contact: hybrid position/force control (5.1)
    hpfc = file["hybrid_force_controller"]
    assert shipped.loop.hpfc is not None and shipped.loop.hpfc_enabled == hpfc["enabled"]
    for key in ("K_p", "T_i", "T_d", "F_th", "v_max", "a_max", "x_max", "T_F"):
        assert getattr(shipped.loop.hpfc, key) == hpfc[key], key
    # load compensation (4.1) and the payload into the force set-point
    lc = file["load_compensation"]
    assert shipped.load_compensation.enabled == lc["enabled"]
    assert shipped.load_compensation.tare_at_start == lc["tare_at_start"]
    assert shipped.payload_input == file["force_distribution"]["payload_input"]
    stage = shipped.offset_stages(robot)["load_compensation"]
    assert isinstance(stage, LoadCompensationStage) and stage.feed_force_setpoint == shipped.payload_input
    assert stage.compensation.params == shipped.load_compensation
    # hand guiding (5.2): every key of the file reaches the controller
    adm = file["admittance_controller"]
    assert shipped.hand_guiding == adm["hand_guiding"]
    controller = shipped.admittance_controller(robot)
    zones = {z.name: z for z in controller.zones.zones}
    for key, value in adm.items():
        if key == "zones.force_margin":          # the fit's margin: the hard box in the narrowed limits' WFW
            check_in_workspace(robot, controller.zones, controller.user.w_max, controller.system.v_max,
                               *force_limits(robot, value))
        elif key.startswith("zones.") and key != "zones.origin":
            _, zone, field = key.split(".")
            actual = zones[zone].size if field in ("box", "radius") else getattr(zones[zone], field)
            np.testing.assert_array_equal(actual, value if field == "radius" else per_axis(value, key), err_msg=key)
        elif key in ("dead_band", "w_max"):
            np.testing.assert_array_equal(getattr(controller.user, key), per_axis(value, key))
        elif key in ("T_filter", "tare_time"):
            assert getattr(controller.params.user, key) == value
        elif key in ("v_max", "a_max"):
            np.testing.assert_array_equal(getattr(controller.system, key), per_axis(value, key))
        else:
            assert key == "hand_guiding", f"{key} is not checked"


def test_overrides_and_switches_win_over_the_file():
    robot = load_robot("ipanema3")
    shipped = shipped_configuration(robot, hpfc_enabled=True, mode="ik_only")
    assert shipped.loop.hpfc_enabled and shipped.loop.mode == "ik_only"
    controller = shipped.admittance_controller(robot, {"T_filter": 0.05})
    assert controller.params.user.T_filter == 0.05


def test_a_robot_without_a_parameter_file_gets_the_library_defaults():
    assert control_loop_params("no_such_robot").hpfc is None
    shipped = shipped_configuration("no_such_robot")
    assert shipped.dt == 1e-3 and shipped.admittance == {} and not shipped.payload_input
