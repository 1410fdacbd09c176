"""Parameter descriptions and validation: errors name the parameter and the allowed values."""

import pytest

from toolbox import Algorithm, Output, Parameter
from toolbox.errors import UsageError


def alg():
    return Algorithm(
        id="p-test", title="t", description="d", run=lambda i, p, c: {},
        parameters=[
            Parameter("cell_size_m", float, 0.5, "cell", unit="m", minimum=0.0, exclusive_minimum=True, maximum=10.0),
            Parameter("votes", int, 15, "votes", minimum=1),
            Parameter("mode", str, "fast", "mode", choices=("fast", "exact")),
            Parameter("first_only", bool, True, "first returns"),
            Parameter("height_max_m", float, None, "top", unit="m", allow_auto=True, minimum=0.0),
        ],
        outputs=[Output("out", "json", "o")],
    )


def test_defaults_fill_every_parameter():
    assert alg().validate_params({}) == {"cell_size_m": 0.5, "votes": 15, "mode": "fast", "first_only": True,
                                         "height_max_m": None}


def test_strings_from_the_command_line_are_coerced():
    v = alg().validate_params({"cell_size_m": "1.5", "votes": "20", "mode": "exact", "first_only": "no",
                               "height_max_m": "auto"})
    assert v == {"cell_size_m": 1.5, "votes": 20, "mode": "exact", "first_only": False, "height_max_m": None}
    assert alg().validate_params({"height_max_m": "12"})["height_max_m"] == 12.0


@pytest.mark.parametrize("given, pattern", [
    ({"cell_size": 1}, r"unknown parameter 'cell_size' \(did you mean 'cell_size_m'\?\); valid parameters: cell_size_m, votes"),
    ({"cell_size_m": 0}, r"cell_size_m: 0.0 is out of range; allowed \(0, 10\]"),
    ({"cell_size_m": "-1"}, r"cell_size_m: -1.0 is out of range"),
    ({"cell_size_m": "1e9"}, r"out of range; allowed \(0, 10\]"),
    ({"cell_size_m": "nan"}, r"not a finite number"),
    ({"cell_size_m": "abc"}, r"cell_size_m: 'abc' is not a number"),
    ({"votes": "1.5"}, r"votes: '1.5' is not an integer"),
    ({"votes": 0}, r"votes: 0 is out of range; allowed \[1, inf\]"),
    ({"mode": "fsat"}, r"mode: 'fsat' is not allowed \(did you mean 'fast'\?\); allowed one of fast, exact"),
    ({"first_only": "maybe"}, r"first_only: 'maybe' is not true or false"),
    ({"votes": True}, r"not of type int"),
])
def test_bad_values_are_usage_errors_naming_the_parameter(given, pattern):
    with pytest.raises(UsageError, match=pattern):
        alg().validate_params(given)


def test_declaring_a_bad_default_fails_at_declaration():
    with pytest.raises(UsageError):
        Parameter("x_m", float, -1.0, "x", minimum=0.0)
    with pytest.raises(ValueError):
        Parameter("BadName", float, 1.0, "x")


def test_algorithm_declaration_is_checked():
    with pytest.raises(ValueError, match="lower-case"):
        Algorithm(id="Bad_Id", title="t", description="d", run=lambda *a: {}, outputs=[Output("o", "json", "o")])
    with pytest.raises(ValueError, match="no output"):
        Algorithm(id="ok-id", title="t", description="d", run=lambda *a: {})
