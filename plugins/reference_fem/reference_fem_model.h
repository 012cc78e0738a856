// The reference_fem model (reference_fem_model.cpp): quadratic or linear tets from Gmsh around
// the organ, Newton solves of FemSystem (fem_solver.h) each step; quasi-static or implicit Euler.
#pragma once

#include "fem_solver.h"

#include <deform/geometry/organ_tets.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <memory>
#include <string>
#include <vector>

namespace deform::reference_fem {

enum class SolveKind { QuasiStatic, Dynamic };

/// Resolved parameters (see paramSpecs() for units, ranges and meaning).
struct ReferenceFemConfig {
  SolveKind solve = SolveKind::QuasiStatic;
  MaterialModel material = MaterialModel::NeoHookean;
  ElementOrder order = ElementOrder::Quadratic;
  VolumetricChoice volumetric = VolumetricChoice::Auto;  ///< resolved against the organ's nu
  SolveOptions options;                                  ///< Newton tolerance and caps
  /// "auto", "float16", "float32", "float64": SolveOptions::preconditionerCopy, auto resolved
  /// at init (float16, float32 without F16C, unless the volumetric term is mean_dilatation, then
  /// float64).
  std::string preconditioner = "auto";
  bool stopAtFold = true;  ///< quasi-static: stop a solve whose surface passes through itself
  Real rayleighAlpha = 0;  ///< 1/s (dynamic only)
  Real rayleighBeta = 0;   ///< s (dynamic only)
  OrganTetOptions mesh;    ///< deform/geometry/organ_tets.h (calculix meshes the same way)
};

std::vector<ParamSpec> paramSpecs();
ReferenceFemConfig configFromParams(const ParamValues& params);

/// The model the plugin registers.
std::unique_ptr<Model> makeReferenceFemModel();

}  // namespace deform::reference_fem
