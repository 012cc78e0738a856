// deformbench harness: results.json (docs/results-format.md) and the surfaces written beside it.
#pragma once

#include <deform/engine/scene.h>
#include <deform_harness/run_record.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace deform::harness {

/// Where and with what the results were produced.
struct MachineInfo {
  std::string cpu;  ///< /proc/cpuinfo model name
  /// The widest vector unit the kernels use here: "avx512" (F, VL, DQ), "avx2", "sse2", or ""
  /// off x86-64. One model name covers CPUs with and without AVX-512, whose speeds differ 2-5x.
  std::string vectorUnits;
  /// Kernels of the OpenBLAS the plugins loaded ("Cooperlake", "Haswell": openblas_get_corename,
  /// which the environment's OPENBLAS_CORETYPE overrides), "" when none is loaded yet or the BLAS
  /// is another. reference_fem's factorisations took 14-27% less with the AVX-512 kernels than
  /// with the AVX2 ones on the AMD EPYC VM (docs/notes/h6-amd-ratios.md).
  std::string blas;
  std::string compiler;   ///< e.g. "GCC 12.2.0"
  std::string buildType;  ///< CMAKE_BUILD_TYPE of the harness
  std::string git;        ///< git describe of the source tree, "" when unavailable
  std::string timestamp;  ///< UTC, ISO 8601
  std::string version;    ///< deformbench version
};
MachineInfo machineInfo();
/// MachineInfo::blas alone: the kernels of the OpenBLAS loaded in this process, "" when none is.
std::string loadedBlasKernels();

/// Folder name for a run label: letters, digits, '.', '-' and '_' kept, everything else '_'.
std::string sanitizeLabel(const std::string& label);

/// Writes each run's surfaces under outDir/<sanitised label>/ (final.obj; a .vtp series with a
/// .pvd for "every:N"; grasp_forces.csv when the model reports forces) and sets the records'
/// file fields. Labels that sanitise to the same folder get a numeric suffix.
void writeRunSurfaces(const std::filesystem::path& outDir, const Scene& scene, const Organ& organ,
                      std::vector<RunRecord>& runs);

/// The organ's rest surface, written beside results.json unless the scene writes no surfaces.
inline constexpr const char* kRestSurfaceFile = "rest_surface.obj";

/// What the viewer draws besides the surfaces: the fixed region (boxes, surface vertices), the
/// tools' trajectories and the loads, in metres and seconds (results.json "interaction").
nlohmann::ordered_json interactionJson(const Scene& scene, const Organ& organ);

/// The results document (keys in the order docs/results-format.md shows them).
nlohmann::ordered_json resultsJson(const Scene& scene, const Organ& organ,
                                   const std::vector<std::string>& organLog,
                                   const std::vector<RunRecord>& runs, const MachineInfo& machine);

/// JSON of one run (an element of "runs").
nlohmann::ordered_json runJson(const RunRecord& run);

/// One element of "runs" read back into a record (the inverse of runJson() for the summary fields:
/// identity, status, message, notes, counts, precompute_s, steps, step_ms, phase_ms, numeric,
/// error; surfaces are not read). A null number reads as NaN. Throws std::exception (a JSON type
/// error, an unknown status) on a malformed element.
RunRecord runFromJson(const nlohmann::json& run);

/// Writes outDir/results.json atomically; returns its path.
std::filesystem::path writeResults(const std::filesystem::path& outDir,
                                   const nlohmann::ordered_json& doc);

}  // namespace deform::harness
