"""Force laws the tests fit, each written once as the text of a user's model file.

The tests that give pamid a model file write the text; the tests that call pamid from
Python use the class made from the same text, so the two can never differ.
"""

QUADRATIC_SOURCE = '''
import pamid

class Quadratic(pamid.ForceModel):
    c0: float = 0.0
    c1: float = 1.0
    c2: float = -10.0
    c3: float = 0.0
    units = {"c0": "N", "c1": "N/kPa", "c2": "N/%", "c3": "N/(kPa*%)"}
    inputs = ("pressure_kPa", "contraction_pct")

    def __call__(self, pressure_kPa, contraction_pct):
        return (self.c0 + self.c1 * pressure_kPa + self.c2 * contraction_pct
                + self.c3 * pressure_kPa * contraction_pct)
'''
"""The model file of the issue "Any model", as written there."""

PLANE_SOURCE = '''
import pamid

class Plane(pamid.ForceModel):
    c0: float = 0.0
    c1: float = 1.0
    c2: float = -10.0
    units = {"c0": "N", "c1": "N/kPa", "c2": "N/%"}
    inputs = ("pressure_kPa", "contraction_pct")

    def __call__(self, pressure_kPa, contraction_pct):
        return self.c0 + self.c1 * pressure_kPa + self.c2 * contraction_pct
'''
"""F = c0 + c1·p + c2·κ: the Quadratic without its interaction term."""


def _class_from(source: str, name: str) -> type:
    namespace: dict = {}
    exec(compile(source, f"<{name} model file>", "exec"), namespace)
    return namespace[name]


Quadratic = _class_from(QUADRATIC_SOURCE, "Quadratic")
Plane = _class_from(PLANE_SOURCE, "Plane")
