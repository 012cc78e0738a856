// TEMPORARY stand-ins for SDK functions declared in core/include/deform/{params,model}.h whose
// implementations land on main from other branches. Weak, so the real definitions in
// libdeform_core win once they exist; delete this file then.
#include <deform/cache.h>
#include <deform/model.h>
#include <deform/params.h>

#include <algorithm>

namespace deform {

[[gnu::weak]] Cache::Cache(std::filesystem::path dir) : m_dir(std::move(dir)) {}

[[gnu::weak]] double ParamValues::real(const std::string& key) const {
  const ParamValue& v = m_values.at(key);
  if (const long long* i = std::get_if<long long>(&v)) return static_cast<double>(*i);
  return std::get<double>(v);
}
[[gnu::weak]] long long ParamValues::integer(const std::string& key) const {
  return std::get<long long>(m_values.at(key));
}
[[gnu::weak]] bool ParamValues::flag(const std::string& key) const {
  return std::get<bool>(m_values.at(key));
}
[[gnu::weak]] const std::string& ParamValues::choice(const std::string& key) const {
  return std::get<std::string>(m_values.at(key));
}
[[gnu::weak]] ParamValues ParamValues::defaults(const std::vector<ParamSpec>& specs) {
  std::map<std::string, ParamValue> m;
  for (const ParamSpec& s : specs) m[s.key] = s.defaultValue;
  return ParamValues(std::move(m));
}

[[gnu::weak]] std::vector<int> fixedNodeIndices(const MatX3& nodes, const FixedRegion& region,
                                                const SurfaceMesh& restSurface) {
  std::vector<int> out;
  for (Eigen::Index i = 0; i < nodes.rows(); ++i)
    for (const Box& b : region.boxes)
      if (b.contains(nodes.row(i).transpose())) out.push_back(static_cast<int>(i));
  for (int v : region.surfaceVertices) out.push_back(nearestVertex(nodes, restSurface.V.row(v)));
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace deform
