// The entry points shared by the libFuzzer targets (tests/fuzz/*_fuzzer.cpp) and the regression
// test that replays every saved crash (tests/unit/fuzz_regressions_test.cpp). They feed bytes
// through the same code a user's file goes through and swallow only the exceptions that are the
// documented answer to bad input: deform::InputError (and, for scenes, the JSON library's own
// syntax errors for text that is not JSON). Anything else escaping (std::bad_alloc,
// std::out_of_range, a nlohmann type_error from inside the parser) ends the process and counts
// as a bug, as do crashes, sanitizer reports, hangs and leaks.
#pragma once

#include <deform/error.h>
#include <deform/mesh_check.h>
#include <deform/mesh_io.h>

#include <string>
#include <string_view>

#if __has_include(<deform/scene.h>)
#include <deform/scene.h>
#endif

namespace deform::fuzz {

/// What happened to one input.
enum class Outcome { Accepted, Refused };

/// Reads `data` as a mesh file called `name` (the extension picks the reader), then runs the
/// validation and the repair on whatever was read, as loadOrgan does.
inline Outcome feedMesh(std::string_view data, const std::string& name) {
  LoadedMesh mesh;
  try {
    mesh = readMeshFromMemory(std::string(data), name);
  } catch (const InputError&) {
    return Outcome::Refused;
  }
  const MeshReport report = validateSurface(mesh.surface);
  (void)report.usable();
  try {
    requireValidSurface(mesh.surface, name);
  } catch (const InputError&) {
  }
  SurfaceMesh repaired = mesh.surface;
  const RepairReport changes = repairSurface(repaired);
  (void)changes.lines();
  (void)validateSurface(repaired);
  return Outcome::Accepted;
}

/// Parses `text` as JSON and then as a scene file ("fuzz/scene.json"; mesh paths resolve
/// relative to it but no mesh is loaded).
inline Outcome feedScene(std::string_view text) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text.begin(), text.end());
  } catch (const nlohmann::json::parse_error&) {
    return Outcome::Refused;
  }
  try {
    (void)parseScene(j, "fuzz/scene.json");
  } catch (const InputError&) {
    return Outcome::Refused;
  }
  return Outcome::Accepted;
}

}  // namespace deform::fuzz
