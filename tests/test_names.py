"""A fitted value's name is one structured reference (spacefit.scene.names.Name), its text read once."""

import json
import pickle

import pytest

from spacefit.scene.names import Name


def test_a_name_is_its_parameter_and_its_observation_and_reads_as_its_text():
    own = Name("target.attitude_x_deg@2")
    assert (own.parameter, own.observation) == ("target.attitude_x_deg", 2)
    assert own == "target.attitude_x_deg@2" == Name("target.attitude_x_deg", 2)
    assert {"target.attitude_x_deg@2": 1.0}[own] == 1.0 and {own: 1.0}["target.attitude_x_deg@2"] == 1.0
    assert json.loads(json.dumps({own: 0.5})) == {"target.attitude_x_deg@2": 0.5}
    shared = own.shared()
    assert (shared, shared.parameter, shared.observation) == ("target.attitude_x_deg", "target.attitude_x_deg", None)


def test_a_name_survives_pickling_with_its_observation():
    """Names travel to dask workers inside a fit's frames."""
    back = pickle.loads(pickle.dumps(Name("image.scale", 3)))
    assert isinstance(back, Name) and (back.parameter, back.observation) == ("image.scale", 3)


@pytest.mark.parametrize("text", ["image.scale@", "image.scale@x", "image.scale@-1", "image.scale@1.5", "image.scale@٣"])
def test_a_mark_without_a_whole_number_stays_in_the_parameter(text):
    name = Name(text)
    assert (name.parameter, name.observation) == (text, None)


def test_a_name_given_again_is_the_same_and_another_observation_moves_it():
    own = Name("image.scale@1")
    assert Name(own) is own and Name(own, 1) is own
    assert Name(own, 4) == "image.scale@4"
