#include <deform_harness/format.h>

#include <cstdio>

namespace deform::harness {

std::string formatG(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

nlohmann::ordered_json vecJson(const Vec3& v) {
  return nlohmann::ordered_json::array({v.x(), v.y(), v.z()});
}

}  // namespace deform::harness
