// particle_bem plugin: registers the surface-guided particle model (particle_bem_model.h).
#include "paper_tables.h"
#include "particle_bem_model.h"

#include <deform/phantom.h>

#include <string>

DEFORM_PLUGIN(registry) {
  registry.add(deform::particle_bem::ParticleBemModel::info());
}

/// Optional extension beyond the two ABI symbols (the harness looks it up with dlsym and does
/// without it when absent): the paper's static accuracy measure, Table 2's R, for the harness
/// table bem-accuracy (paper_tables.h, bemStaticAccuracy). `request` is JSON:
///   {"organ": "phantom:liver", "rows": [[coarse, fine], ...], "cache_dir": "..."}
/// (organ: a phantom name; cache_dir absent or empty: no caching). Returns JSON owned by the
/// plugin, valid until the calling thread's next call: {"rows": [...]} or {"error": "..."}.
DEFORM_PLUGIN_EXPORT const char* deform_particle_bem_static_accuracy(const char* request) {
  thread_local std::string reply;
  try {
    const nlohmann::json q = nlohmann::json::parse(request ? request : "");
    const std::string organ = q.value("organ", std::string("phantom:liver"));
    if (organ.rfind("phantom:", 0) != 0)
      throw deform::InputError("static accuracy request", "organ",
                               "'" + organ + "' is not a phantom (phantom:NAME)");
    std::vector<std::pair<int, int>> rows;
    for (const auto& r : q.at("rows")) rows.emplace_back(r.at(0).get<int>(), r.at(1).get<int>());
    const deform::SurfaceMesh mesh = deform::makePhantom(organ.substr(8));
    reply = nlohmann::json{{"rows", deform::particle_bem::bemStaticAccuracy(
                                        mesh, rows, q.value("cache_dir", std::string()))}}
                .dump();
  } catch (const std::exception& e) {
    reply = nlohmann::json{{"error", e.what()}}.dump();
  }
  return reply.c_str();
}
