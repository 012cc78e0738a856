// The entry points shared by the libFuzzer targets (tests/fuzz/*_fuzzer.cpp) and the regression
// test that replays every saved crash (tests/unit/fuzz_regressions_test.cpp). They feed bytes
// through the same code a user's file goes through and swallow only the exceptions that are the
// documented answer to bad input: deform::InputError (and, for scenes parsed from a JSON value,
// the JSON library's own exceptions from json::parse; parseSceneFile must turn those into
// InputError itself). Anything else escaping (std::bad_alloc,
// std::out_of_range, a nlohmann type_error from inside the parser) ends the process and counts
// as a bug, as do crashes, sanitizer reports, hangs and leaks.
#pragma once

#include <deform/engine/scene.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/sdk/error.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace deform::fuzz {

/// What happened to one input.
enum class Outcome { Accepted, Refused };

/// Reads `data` as a mesh file called `name` (the extension picks the reader), then runs the
/// validation and the repair on whatever was read, as loadOrgan does, and the self-intersection
/// test.
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
  // The self-intersection test that tetrahedralize() runs before Gmsh, on the raw surface (any
  // triangle soup: bad triangles are skipped) and on the repaired one.
  (void)findSelfIntersections(mesh.surface).message();
  try {
    requireNoSelfIntersections(repaired, name);
  } catch (const InputError&) {
  }
  return Outcome::Accepted;
}

/// Feeds `text` to the scene parser both ways a scene arrives: as a JSON value
/// (json::parse, whose own exceptions are accepted, then parseScene(j, "fuzz/scene.json")) and
/// as a file (parseSceneFile, which also refuses duplicate keys and must turn every JSON error
/// into InputError with the place).
/// Mesh paths resolve relative to the file but no mesh is loaded. Refused if either refuses.
inline Outcome feedScene(std::string_view text) {
  Outcome outcome = Outcome::Accepted;
  nlohmann::json j;
  bool parsed = false;
  try {
    j = nlohmann::json::parse(text.begin(), text.end());
    parsed = true;
  } catch (const nlohmann::json::exception&) {  // syntax error, or a number overflowing a double
    outcome = Outcome::Refused;
  }
  if (parsed) {
    try {
      (void)parseScene(j, "fuzz/scene.json");
    } catch (const InputError&) {
      outcome = Outcome::Refused;
    }
  }
  // One scratch file per process, rewritten for every input.
  static const std::string path = (std::filesystem::temp_directory_path() /
                                   ("deform_fuzz_scene_" + std::to_string(getpid()) + ".json"))
                                      .string();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
  }
  try {
    (void)parseSceneFile(path);
  } catch (const InputError&) {
    outcome = Outcome::Refused;
  }
  std::remove(path.c_str());
  return outcome;
}

}  // namespace deform::fuzz
