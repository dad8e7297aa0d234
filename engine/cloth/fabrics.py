"""Fabrics with physical parameters, from published measurements.

Sources (typical values; real bolts vary by +-30 %):
- Area density: fabric weights as sold. Cotton shirting/poplin 100-130 g/m^2; denim 12-14 oz/yd^2
  (1 oz/yd^2 = 33.9 g/m^2, so 407-475 g/m^2); silk charmeuse 16-19 momme (1 momme = 4.3 g/m^2,
  so 69-81 g/m^2); cotton single jersey 150-200 g/m^2.
- Bending rigidity B and extensibility: Kawabata Evaluation System (KES-F) measurements,
  S. Kawabata & M. Niwa, "Fabric performance in clothing and clothing manufacture", J. Textile
  Inst. 80(1), 1989, and the KES-FB tables in B. K. Behera & P. K. Hari, "Woven textile structure"
  (Woodhead 2010), ch. 11: B in gf.cm^2/cm (1 gf.cm^2/cm = 9.81e-5 N.m) ~0.05-0.15 for shirting,
  0.5-1.5 for denim, 0.01-0.04 for silk, 0.02-0.06 for jersey; EMT (strain at 500 gf/cm) ~3-6 %
  for shirting, 2-5 % for denim, 3-8 % for silk, 20-60 % for knit jersey. Stretch stiffness
  here is the secant 500 gf/cm / EMT (= 490 N/m / EMT).
- In-plane shear stiffness: KES-FB1 G (gf/cm.deg) ~0.5-1.5 for shirting, 1.5-4 for denim,
  0.2-0.6 for silk, 0.2-0.5 for jersey; per radian: G * 0.981 N/m / (pi/180) = 56.2 N/m per unit.
- Cloth-skin friction: Gwosdow et al., "Skin friction and fabric sensations in neutral and warm
  environments", Textile Research J. 56(9), 1986: mu ~0.3-0.5 for cotton, ~0.25 for silk,
  ~0.4-0.6 for denim and knits.
- Strain thresholds for the velocity modification (seed 003 §4.3 uses 1-15 % by fabric type):
  about the strain a garment shows in wear — small for woven fabrics, larger for knits.
- Shear locking angle (`shear_lock`): a woven fabric shears freely -- its yarns turn about their
  crossings, which is how it takes a doubly curved shape (bust, shoulder, hip) without stretching
  -- until the yarns jam, in picture-frame and bias-extension tests typically at 30-45 degrees
  for plain weaves, earlier for dense ones (denim); knit loops turn further. The strain limit
  measures a quad's diagonal from the length that shear gives it, sqrt(1 + sin angle) x rest (at
  30 degrees 22.5 % longer; engine.cloth.model.limit_rest), not from its rest length: 5 % on a
  diagonal is 6 degrees of shear, and a cotton that could shear no more could not wrap an armpit
  or a bust without stretching its yarns. (A border triangle's slanted edge keeps the plain
  limit: no yarn beside it would hold the yarns' stretch.) Every preset holds its diagonals at the
  stretch threshold for now (shear_lock 0): at 30 degrees for cotton the catalogue's drapes took
  1.7x the iterations and default:male's trousers in L slid 11 cm down the hips (docs/tuning.md,
  `Fabric.shear_lock`), against 2 more of 100 GarmentCode designs.
- Elastane (spandex, Lycra) knits, `stretch_knit`: leggings, swimwear, activewear. Elastane raises
  a single jersey's area density by 23-63 % over the same jersey without it (Akter et al.,
  "Performance analysis of spandex incorporated single jersey fabrics for sportswear", Indian J.
  Sci. Technol. 13(20), 2020): 180-250 g/m^2 in cotton/elastane, 200-300 g/m^2 in the nylon/
  elastane of leggings. It takes less force to stretch it at every extension than a cotton knit
  (Senthilkumar & Anbumani, "Dynamic elastic behavior of cotton and cotton/spandex knitted
  fabrics", J. Engineered Fibers and Fabrics 6(3), 2011); a four-way stretch knit extends 75-100 %
  before it locks (sewing suppliers' figures), so its EMT at 500 gf/cm is 60-100 %. Such garments
  are cut with negative ease, smaller than the body, and worn stretched: a pattern maker drafts
  them to use about half the fabric's stretch, and "power stretch" fabrics are those made to
  be worn 30-50 % stretched (comfort stretch: under 30 %; K. L. Hatch, "Textile Science", 1993,
  on stretch fabrics). Leggings cut 16-18 % under the hips stretch 19-22 % round them on average
  and more where the body curves (seat, calf), so its threshold is 40 %.
- Rib knit, `rib_knit`: the cuffs, waistbands and neckbands of knitwear and sweatshirts. A 1x1
  rib's wales close up when relaxed, so it stretches crosswise to about twice its width and
  recovers (sewing suppliers' ribbing guides ask for 75-100 % crosswise stretch); a band is cut
  a quarter to a third shorter than the opening it is sewn into and stretched over the hand or
  hips to go on, so it is worn 30-80 % stretched: its threshold is 80 %. With elastane,
  220-300 g/m^2. The try-on sews from it the parts of a pattern file cut smaller round than the
  body where they stay too tight in stretch_knit (engine.scene.tryon.RIB_KNIT), as a maker does.
  It is soft crosswise only (`Fabric.crosswise`): lengthwise its springs keep the floor below.

The simulation uses the measured stretch and shear stiffness times `ClothParams.stiffness_scale`
(default 0.03): the velocity modification caps the strain at the threshold, which is the point of
seed 003 §4 -- softer springs allow a larger stable time step (eq. 4), but much softer springs let
the strain limit lose where the body pushes cloth outward (a waistband on the hips), so the
default stays at 0.03 (docs/tuning.md, `stiffness_scale`). No fabric's springs are softer for its
weight than cotton's (`ClothParams.sag_as`): scaled alone, jersey's and stretch_knit's would let
them sag under their own weight toward their thresholds (a gown hanging 12 % longer than cut),
where a real knit stretches well under 1 %; so a knit takes cotton's eq. 4 step, and its
stretchiness is its threshold.
"""

from __future__ import annotations

from dataclasses import dataclass

from engine.errors import InputError

GF_CM2_PER_CM = 9.81e-5  # N.m per gf.cm^2/cm (KES bending rigidity unit)
G_UNIT = 56.2  # N/m per rad for 1 gf/(cm.deg) (KES shear stiffness unit)


@dataclass(frozen=True)
class Fabric:
    name: str
    density: float  # kg/m^2
    stretch: float  # N/m, tensile stiffness (force per width per unit strain)
    shear: float  # N/m, in-plane shear stiffness per radian
    bending: float  # N.m, bending rigidity per unit width
    friction: float  # cloth-skin Coulomb friction coefficient (dimensionless)
    strain_threshold: float  # velocity modification threshold (fraction, seed 003 §4.3)
    # degrees: the in-plane shear the strain limit lets a quad's diagonals take (see the module doc;
    # 0: none -- the diagonals held at the stretch threshold, as every preset is for now)
    shear_lock: float = 0.0
    # soft crosswise only (a rib: its wales close up across it, its loops hold along it): its
    # lengthwise springs keep ClothParams.sag_as's floor, its crosswise and bias ones are its own
    # (the strain limit, its threshold, is the same both ways)
    crosswise: bool = False
    note: str = ""


FABRICS: dict[str, Fabric] = {
    f.name: f
    for f in (
        Fabric("cotton", density=0.120, stretch=490 / 0.045, shear=0.9 * G_UNIT, bending=0.10 * GF_CM2_PER_CM,
               friction=0.40, strain_threshold=0.05, note="cotton shirting/poplin, 120 g/m^2"),
        Fabric("denim", density=0.420, stretch=490 / 0.035, shear=2.5 * G_UNIT, bending=1.0 * GF_CM2_PER_CM,
               friction=0.50, strain_threshold=0.03, note="12.5 oz/yd^2 denim, 420 g/m^2"),
        Fabric("silk", density=0.075, stretch=490 / 0.05, shear=0.4 * G_UNIT, bending=0.025 * GF_CM2_PER_CM,
               friction=0.25, strain_threshold=0.05, note="17.5 momme silk charmeuse, 75 g/m^2"),
        Fabric("jersey", density=0.180, stretch=490 / 0.35, shear=0.3 * G_UNIT, bending=0.04 * GF_CM2_PER_CM,
               friction=0.50, strain_threshold=0.15, note="cotton single jersey knit, 180 g/m^2"),
        Fabric("stretch_knit", density=0.230, stretch=490 / 0.80, shear=0.2 * G_UNIT, bending=0.03 * GF_CM2_PER_CM,
               friction=0.50, strain_threshold=0.40, note="cotton or nylon/elastane jersey (leggings), 230 g/m^2"),
        Fabric("rib_knit", density=0.260, stretch=490 / 1.20, shear=0.2 * G_UNIT, bending=0.05 * GF_CM2_PER_CM,
               friction=0.50, strain_threshold=0.80, crosswise=True,
               note="1x1 cotton/elastane rib (cuffs, bands), 260 g/m^2"),
    )
}


DEFAULT_FABRIC = "cotton"  # where neither the user nor the pattern names one


def get_fabric(name: str | None) -> Fabric:
    """The fabric `name` (None: DEFAULT_FABRIC)."""
    try:
        return FABRICS[name or DEFAULT_FABRIC]
    except KeyError:
        raise InputError(f"unknown fabric '{name}'; choose one of: {', '.join(FABRICS)}") from None
