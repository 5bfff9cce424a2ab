"""Body measurements for procedural avatars, drawn from published adult distributions.

Adults: stature, biacromial (shoulder) breadth, hip breadth and chest depth per sex, means and standard
deviations rounded from the summary tables of the 2012 US Army anthropometric survey, ANSUR II (Gordon
C. C. et al., *2012 Anthropometric Survey of U.S. Army Personnel: Methods and Summary Statistics*,
NATICK/TR-15/007, 2014). Breadths and depth are drawn correlated with stature (r = ``BREADTH_R``, the
order of the survey's stature–breadth correlations), each truncated at ±3 SD.

Older adults (``OLDER_SHARE`` of the pool) lose ``OLDER_STATURE_LOSS_M`` of stature (the 2–4 cm
age-related loss reported by longitudinal studies, e.g. Sorkin et al., Am. J. Epidemiol. 1999) and keep
the breadths. Children (``CHILD_SHARE``) are 6–12 years old with stature from the CDC 2000 growth
charts' medians (about 1.16 m at 6 to 1.52 m at 12, sexes pooled; SD ≈ 5.5 cm) and breadths in
proportion to stature (``CHILD_BREADTH_RATIO``), with a larger head for their height.

An army survey is leaner and younger than a general public; it is the largest openly published adult
survey with these dimensions, which is why it is the reference. All lengths are metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# (mean, sd) in metres, ANSUR II summary statistics (rounded)
ANSUR_II = {
    "male": {
        "stature": (1.756, 0.0686),
        "biacromial": (0.4157, 0.0192),
        "hip": (0.344, 0.022),
        "chest_depth": (0.253, 0.020),
    },
    "female": {
        "stature": (1.629, 0.0642),
        "biacromial": (0.3651, 0.0184),
        "hip": (0.363, 0.025),
        "chest_depth": (0.239, 0.021),
    },
}
BREADTH_R = 0.45  # correlation of each breadth with stature
TRUNCATE_SD = 3.0
OLDER_SHARE = 0.15
OLDER_STATURE_LOSS_M = 0.03
CHILD_SHARE = 0.08
CHILD_AGE = (6.0, 12.0)
CHILD_STATURE_AT_6_M, CHILD_GROWTH_M_PER_YEAR, CHILD_STATURE_SD_M = 1.16, 0.06, 0.055
CHILD_BREADTH_RATIO = {"biacromial": 0.235, "hip": 0.2, "chest_depth": 0.135}  # × stature
CHILD_HEAD_SCALE = 1.18  # head size relative to an adult head scaled to the same stature


@dataclass(frozen=True)
class Body:
    """One identity's measurements.

    Attributes:
        sex: ``male`` or ``female``.
        age_group: ``child``, ``adult`` or ``older``.
        stature_m: standing height.
        biacromial_m: shoulder breadth between the acromia.
        hip_m: hip breadth.
        chest_depth_m: chest depth.
        head_scale: head size relative to the adult proportion at this stature.
    """

    sex: str
    age_group: str
    stature_m: float
    biacromial_m: float
    hip_m: float
    chest_depth_m: float
    head_scale: float = 1.0

    @property
    def body_radius_m(self) -> float:
        """Radius of a vertical cylinder around the torso and hanging arms.

        About half the bideltoid breadth, itself about 1.18 × the biacromial breadth.
        """
        return round(0.5 * max(1.18 * self.biacromial_m, self.hip_m + 0.04), 4)


def _truncated_normal(rng: np.random.Generator) -> float:
    while True:
        z = float(rng.normal())
        if abs(z) <= TRUNCATE_SD:
            return z


def sample_body(rng: np.random.Generator, child_share: float = CHILD_SHARE, older_share: float = OLDER_SHARE) -> Body:
    """Draw one identity's sex, age group and measurements (see the module docstring)."""
    sex = "female" if rng.random() < 0.5 else "male"
    u = rng.random()
    group = "child" if u < child_share else "older" if u < child_share + older_share else "adult"
    if group == "child":
        age = rng.uniform(*CHILD_AGE)
        stature = CHILD_STATURE_AT_6_M + CHILD_GROWTH_M_PER_YEAR * (age - CHILD_AGE[0])
        stature += CHILD_STATURE_SD_M * _truncated_normal(rng)
        jitter = {k: 1.0 + 0.05 * _truncated_normal(rng) for k in CHILD_BREADTH_RATIO}
        return Body(
            sex,
            group,
            round(stature, 4),
            round(CHILD_BREADTH_RATIO["biacromial"] * stature * jitter["biacromial"], 4),
            round(CHILD_BREADTH_RATIO["hip"] * stature * jitter["hip"], 4),
            round(CHILD_BREADTH_RATIO["chest_depth"] * stature * jitter["chest_depth"], 4),
            CHILD_HEAD_SCALE,
        )
    table = ANSUR_II[sex]
    z_stature = _truncated_normal(rng)

    def correlated(name: str) -> float:
        mean, sd = table[name]
        z = BREADTH_R * z_stature + np.sqrt(1 - BREADTH_R**2) * _truncated_normal(rng)
        return round(mean + sd * float(np.clip(z, -TRUNCATE_SD, TRUNCATE_SD)), 4)

    mean, sd = table["stature"]
    stature = mean + sd * z_stature - (OLDER_STATURE_LOSS_M if group == "older" else 0.0)
    return Body(sex, group, round(stature, 4), correlated("biacromial"), correlated("hip"), correlated("chest_depth"))
