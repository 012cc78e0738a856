// libFuzzer target for one mesh reader: DEFORM_FUZZ_MESH_NAME ("fuzz.obj", ...) picks the format.
#include <cstddef>
#include <cstdint>

#include "fuzz_entry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  deform::fuzz::feedMesh(std::string_view(reinterpret_cast<const char*>(data), size),
                         DEFORM_FUZZ_MESH_NAME);
  return 0;
}
