"""The COLREGS vocabulary: what a rules file may test and set.

The inference engine (:mod:`trafficsim.colregs.network`) attaches no meaning to any name; this
module declares them. Features are per directed pair (own ship, other ship), in the units their
names carry:

* the encounter geometry of :mod:`trafficsim.colregs.features` (range, bearing, aspect, DCPA,
  TCPA, bow-crossing range, speed ratio, ship domain and time to domain entry, visibility), from
  the own ship's estimates;
* the pair's memory, kept by :mod:`trafficsim.colregs.decider` between decision steps:

  ========================  ==================================================================
  ``own_role``              the own ship's role towards the other: ``no_role``, ``give_way``,
                            ``stand_on``, ``mutual_give_way`` (both ships alter to starboard,
                            as in a head-on encounter, Rule 14); kept until a node sets another
                            (Rule 13(d))
  ``encounter``             ``no_encounter``, ``head_on``, ``crossing``, ``overtaking``,
                            ``overtaken``, ``restricted_visibility``
  ``other_role``            the role the own ship expects of the other (same constants)
  ``own_manoeuvre``         what the pair asks of the own ship: ``no_action``, ``keep``,
                            ``alter_course``, ``reduce_speed``, ``resume_route``, ``emergency``
  ``time_in_role_min``      minutes since ``own_role`` was last set (0 without a role)
  ``other_course_change_deg``  change of the other's course over ground since the role was
                            set, absolute, degrees (0 without a role)
  ``other_speed_change_ratio``  the other's speed over ground now / when the role was set
                            (1 without a role)
  ``own_course_change_deg``  the own ship's course order now minus its route course, degrees,
                            + = starboard (0 when following the route)
  ========================  ==================================================================

Action fields (each kept by the pair until a node sets it again): ``role``, ``encounter``,
``other_role`` (constants as above), ``manoeuvre`` (what the pair asks), ``direction``
(``starboard``, ``port``, ``either``: the side the course alteration must go to),
``course_change_deg`` (the least alteration, degrees), ``speed_factor`` (below 1: also reduce
speed, to this fraction of the route speed) and ``pass_distance_nm`` (the distance
at the closest point of approach the manoeuvre must achieve).
"""

from __future__ import annotations

import math

from trafficsim.colregs import features
from trafficsim.colregs.rulefile import ActionField, EngineParameter, Vocabulary

ROLES = ("no_role", "give_way", "stand_on", "mutual_give_way")
ENCOUNTERS = ("no_encounter", "head_on", "crossing", "overtaking", "overtaken",
              "restricted_visibility")
MANOEUVRES = ("no_action", "keep", "alter_course", "reduce_speed", "resume_route", "emergency")
DIRECTIONS = ("starboard", "port", "either")

#: enum constant -> value; each group in its own decade so that every value names one constant
ENUMS: dict[str, float] = {
    **{name: float(k) for k, name in enumerate(ROLES)},
    **{name: 10.0 + k for k, name in enumerate(ENCOUNTERS)},
    **{name: 20.0 + k for k, name in enumerate(MANOEUVRES)},
    **{name: 30.0 + k for k, name in enumerate(DIRECTIONS)},
}

NO_ROLE, GIVE_WAY, STAND_ON, MUTUAL_GIVE_WAY = (ENUMS[n] for n in ROLES)
NO_ACTION, KEEP, ALTER_COURSE, REDUCE_SPEED, RESUME_ROUTE, EMERGENCY = (
    ENUMS[n] for n in MANOEUVRES)
STARBOARD, PORT, EITHER = (ENUMS[n] for n in DIRECTIONS)

#: memory features, after the geometry features (see the module docstring)
MEMORY = ("own_role", "encounter", "other_role", "own_manoeuvre", "time_in_role_min",
          "other_course_change_deg", "other_speed_change_ratio", "own_course_change_deg")

FEATURES = features.NAMES + MEMORY

ACTIONS: dict[str, ActionField] = {
    "role": ActionField(ROLES, "the own ship's role towards the other"),
    "encounter": ActionField(ENCOUNTERS, "the kind of encounter"),
    "other_role": ActionField(ROLES, "the role expected of the other ship"),
    "manoeuvre": ActionField(MANOEUVRES, "what this encounter asks of the own ship"),
    "direction": ActionField(DIRECTIONS, "side of a course alteration"),
    "course_change_deg": ActionField((), "least course alteration, degrees", (0.0, 180.0)),
    "speed_factor": ActionField((), "largest speed as a fraction of the route speed",
                                (0.0, 1.0)),
    "pass_distance_nm": ActionField((), "distance at CPA the manoeuvre must achieve, NM",
                                    (0.0, math.inf)),
}

#: parameters the decision step reads from a rules file itself (defaults in the decider)
ENGINE_PARAMETERS: dict[str, EngineParameter] = {
    "look_ahead_min": EngineParameter("the look-ahead of time to domain entry and of the "
                                      "arbitration, minutes"),
    "lost_track_min": EngineParameter("how long a lost track keeps its encounter, minutes",
                                      at_least=True),
}

#: the values the bounded features take (geometry: :data:`trafficsim.colregs.features.RANGES`;
#: memory: the table above; the enum-valued ones are compared with their constants)
FEATURE_RANGES: dict[str, tuple[float, float]] = {
    **features.RANGES, "time_in_role_min": (0.0, math.inf),
    "other_course_change_deg": (0.0, 180.0), "other_speed_change_ratio": (0.0, math.inf),
    "own_course_change_deg": (-180.0, 180.0)}

VOCABULARY = Vocabulary(features=FEATURES, enums=ENUMS, actions=ACTIONS,
                        engine_parameters=ENGINE_PARAMETERS, feature_ranges=FEATURE_RANGES)
