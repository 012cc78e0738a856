// deformbench converge: is the scene's reference converged? Three mesh sizes and Richardson.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/convergence.h>
#include <deform_harness/progress.h>

#include <cmath>
#include <iostream>

namespace deform::harness::cli {

namespace {

struct ConvergeArgs {
  std::string scene;
  CommonArgs common;
  long long elements = 0;
  double edgeLength = 0;
  bool ofReference = false;
  ChildArgs child;

  void declare(CLI::App* converge) {
    converge->add_option("scene", scene, "scene file with a reference")->required();
    converge->add_option("--out", common.out, "output folder")->required();
    converge
        ->add_option("--edge-length", edgeLength,
                     "coarsest level's edge length h in m (levels h, h/1.4, h/2; default: the "
                     "reference's own)")
        ->check(positiveValue(false));
    converge
        ->add_option("--elements", elements,
                     "coarsest level's h as the edge length of about this many tets")
        ->check(positiveValue(true));
    converge->add_flag(
        "--of-reference", ofReference,
        "levels 2h, 1.4h and h of the reference's own size h: the estimate is the "
        "error of the reference as the scene runs it (cached; `run` then prints it)");
    addCommon(converge, common, false);
    addChildArgs(converge, child, "level");
  }
};

int cmdConverge(ConvergeArgs& args, const CLI::App& cmd) {
  args.child.given = childArgsGiven(cmd);
  if (args.elements > 0 && args.edgeLength > 0)
    throw InputError("converge", "--elements", "give --elements or --edge-length, not both");
  const CommonArgs& a = args.common;
  const ChildArgs& ch = args.child;
  const std::string& scene = args.scene;
  const long long elements = args.elements;
  const double edgeLength = args.edgeLength;
  const bool ofReference = args.ofReference;
  PluginLoader loader(searchPath(a.pluginDirs));
  ConvergeOptions o = ofReference ? referenceCheckOptions() : ConvergeOptions();
  o.outDir = makeOutDir(a.out);
  o.cacheDir = cacheChoice(a);
  o.baseElements = elements;
  o.baseEdgeLength = edgeLength;
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(ch.dispatch);
  o.dispatcher = dispatcher.get();
  o.child = childOptions(ch, loader, 86400);
  if (ofReference) {
    if (elements > 0 || edgeLength > 0)
      throw InputError("--of-reference", "",
                       "takes the reference's own size: drop --elements and --edge-length");
  }
  ConvergenceResult r;
  {
    Progress progress(0, "converge");
    r = runConvergence(scene, loader, o, &progress);
  }
  for (const auto& l : r.levels) {
    std::cout << "level: ";
    if (l.targetH > 0) {
      std::cout << "target h = " << fmt(1e3 * l.targetH) << " mm";
    } else {
      std::cout << l.targetElements << " target elements";
    }
    std::cout << ": " << l.elements << " elements, h = " << fmt(1e3 * l.h)
              << (r.graded ? " mm (the graded size field's scale)" : " mm")
              << ", peak |u| = " << fmt(1e3 * l.peakDisplacement) << " mm, " << l.status << ", "
              << fmt(l.solveS) << " s\n";
  }
  if (r.cached)
    std::cout << "(the study was read from the precomputation cache; --no-cache reruns it)\n";
  if (r.reason == "levels_failed") {
    std::cout << "warning: " << r.message << "\n";
    return 0;
  }
  std::cout << "max surface difference between levels: " << fmt(1e3 * r.d01) << " mm, then "
            << fmt(1e3 * r.d12) << " mm (vertices near loads and grasps left out); RMS "
            << fmt(1e3 * r.rms01) << " mm, then " << fmt(1e3 * r.rms12) << " mm\n";
  if (std::isnan(r.relativeError)) {
    std::cout << "warning: " << r.message;
    if (std::isfinite(r.boundRelative))
      std::cout << "; the levels differ by up to " << fmt(100 * r.boundRelative)
                << "% of the peak displacement";
    std::cout << "\n";
  } else {
    // With a finer level added, the estimate is the reference's: the level before the last.
    const size_t of = r.estimatedIndex();
    if (r.finerLevelAdded)
      std::cout << "the coarse levels are bound by the surface: a level finer than the reference "
                   "was added, and the estimate is the reference's (level "
                << of << ")\n";
    std::cout << "observed order p = " << fmt(r.order) << ", estimated error of "
              << (r.finerLevelAdded ? "the reference" : "the finest level") << " "
              << fmt(1e3 * r.errorEstimate) << " mm = " << fmt(100 * r.relativeError)
              << "% of the peak displacement\n";
  }
  if (std::isfinite(r.rmsRelativeError))
    std::cout << "RMS differences: observed order p = " << fmt(r.rmsOrder)
              << ", estimated RMS error " << fmt(100 * r.rmsRelativeError)
              << "% of the peak displacement\n";
  if (!r.converged) {
    if (!std::isnan(r.relativeError))
      std::cout << "warning: the reference is not shown converged to 1%"
                << (r.asymptotic ? "" : " (" + r.message + ")")
                << ": refine it (a smaller \"edge_length\") or read its errors as bounds of that "
                   "size\n";
  } else {
    const size_t of = r.estimatedIndex();
    std::cout << "the reference is converged to within 1% at " << r.levels[of].elements
              << " elements\n";
  }
  return 0;
}

}  // namespace

Verb addConverge(CLI::App& app) {
  return makeVerb<ConvergeArgs>(app, "converge",
                                "is the scene's reference converged? three mesh sizes + Richardson",
                                cmdConverge);
}

}  // namespace deform::harness::cli
