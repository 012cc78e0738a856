// The papers' own figures, as data in one place (copied from the papers in ../shared/papers):
// each table prints them beside ours.
#pragma once

#include <map>
#include <string>

namespace deform::harness::tables {

// ---- metaballs paper (Pan et al. 2015)

struct MetaballsPaperRow {
  const char* organ;
  int vertices, spheres, links;
  double constructionS, deformationMs;
};
// Pan et al. 2015, Table 1.
inline constexpr MetaballsPaperRow kMetaballsTable1[] = {
    {"liver", 8128, 581, 3588, 2207, 7.5},
    {"gallbladder", 1461, 475, 3293, 1179, 2.9},
    {"stomach", 3349, 452, 3161, 2050, 8.1},
    {"intestine", 887, 383, 2625, 754, 1.2},
};

struct MethodPaperCell {
  const char* counts;
  double ms;
};
// Pan et al. 2015, Table 2: elements/constraints and deformation ms, gallbladder then liver.
inline const std::map<std::string, std::map<std::string, MethodPaperCell>>& methodPaper() {
  static const std::map<std::string, std::map<std::string, MethodPaperCell>> m = {
      {"gallbladder",
       {{"fem_hex", {"819", 39.2}},
        {"massspring", {"4991", 0.75}},
        {"pbd", {"4991 + 3185", 1.15}},
        {"metaballs", {"3242 + 466", 2.7}}}},
      {"liver",
       {{"fem_hex", {"967", 48.6}},
        {"massspring", {"6427", 2.5}},
        {"pbd", {"6427 + 4079", 2.2}},
        {"metaballs", {"3588 + 581", 7.6}}}}};
  return m;
}

// ---- particles + BEM paper (Zhu, Gu & Zhou 2010)

struct BemTimingPaperRow {
  int model, points;
  double surfaceMs, correctionMs, interpolationMs, overallMs;
};
// Zhu, Gu & Zhou 2010, Table 1.
inline constexpr BemTimingPaperRow kBemTable1[] = {{1, 284, 0.63, 0.228, 0.137, 1.00},
                                                   {2, 508, 1.13, 0.309, 0.266, 1.67},
                                                   {3, 784, 1.75, 0.653, 0.422, 2.83},
                                                   {4, 876, 1.94, 0.725, 0.497, 3.162},
                                                   {5, 1144, 2.53, 1.012, 0.634, 4.176}};

struct BemAccuracyPaperRow {
  int coarse, fine, finePolygons;
  double ratio, loss;  ///< vertex ratio fine/coarse; accuracy loss ratio (fraction)
};
// Zhu, Gu & Zhou 2010, Table 2, plus 608/1216 (vertex ratio 2, the goal; ratio 0: no
// paper value).
inline constexpr BemAccuracyPaperRow kBemTable2[] = {
    {284, 256, 508, 0.90, 0.021},  {284, 394, 784, 1.39, 0.037},   {284, 574, 1144, 2.02, 0.051},
    {608, 506, 1008, 0.83, 0.014}, {608, 1000, 1996, 1.64, 0.033}, {608, 1216, 2428, 0, 0},
    {608, 1586, 3168, 2.61, 0.062}};

// ---- hybrid FEM+PBD paper (Scientific Programming 2021)

inline const char* const kHybridNote =
    "The paper's table figures are not in the project's copy of the paper (lost in text "
    "extraction, see plugins/hybrid_fem_pbd/README.md); its columns are empty rather than "
    "guessed.";

// ---- published benchmark figures (the verification table)

// Cook's membrane, compressible: deal.II code gallery, Quasi_static_Finite_strain_Compressible_
// Elasticity (Pelteret & McBride 2016, doi:10.5281/zenodo.1228964), README "Tip y-displacement",
// Q2 at 64 elements per edge (3d, plane strain, the midpoint (48, 52) mm of the loaded edge):
// 14.74 mm. Its inputs (parameters.prm, cook_membrane.cc): mu 0.4225e6 Pa, nu 0.3, a dead
// traction totalling 1 N on the 16 mm x 1 mm edge along +y, the left edge clamped; its
// volumetric energy is kappa/4 (J^2 - 1 - 2 ln J), not the reference's kappa/2 (J - 1)^2.
inline constexpr double kCooksCompressibleTip = 14.74e-3;  // m
inline const char* const kCooksCompressibleSource =
    "deal.II code gallery Quasi_static_Finite_strain_Compressible_Elasticity, README, Q2 at 64 "
    "elements per edge (doi:10.5281/zenodo.1228964)";

// Cook's membrane, nearly incompressible: OpenGeoSys Tests/Data/LargeDeformation/CooksMembrane
// (CooksMembraneFbar.py, CooksMembrane.prj): Neo-Hookean K/2 (J - 1)^2 + G/2 (J^-2/3 I1 - 3)
// with E 240.565 MPa, nu 0.499 (G 80.1938 MPa, K 4.00942e4 MPa, from de Souza Neto et al. 1996),
// 6.25 MPa shear on the right edge, plane strain; F-bar, 30 elements per side: the top right
// corner (48, 60) mm rises 6.8914 mm (locking elements: 2.29-4.70 mm).
inline constexpr double kCooksIncompressibleTip = 6.8914e-3;  // m
inline const char* const kCooksIncompressibleSource =
    "OpenGeoSys Tests/Data/LargeDeformation/CooksMembrane, F-bar at 30 elements per side "
    "(after de Souza Neto et al. 1996, doi:10.1016/0020-7683(95)00259-6)";

inline const char* const kCooksNote =
    "Cook's membrane, compressible: the deal.II gallery's README gave 14.33 mm until its 2021 "
    "correction (commit 7f3b249: the evaluation point and the 3d plane-strain set-up of Miehe "
    "1994); its current converged figure, used here, is 14.74 mm. Its volumetric energy "
    "kappa/4 (J^2 - 1 - 2 ln J) differs from the reference's kappa/2 (J - 1)^2 at third order "
    "in J - 1.";

}  // namespace deform::harness::tables
