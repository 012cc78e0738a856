// deformbench core, not part of the SDK: atomic file writes, shared by the cache (sdk) and the
// harness's result files. Plugins never write files outside their cache entries.
#pragma once

#include <filesystem>
#include <string_view>

namespace deform {

/// Writes a file atomically: a temporary file beside it, flushed, then renamed over the target.
/// Throws InputError(path, "", reason) on failure.
void writeFileAtomic(const std::filesystem::path& path, std::string_view contents);

}  // namespace deform
