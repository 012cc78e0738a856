// libFuzzer target for the scene parser: JSON text -> nlohmann::json -> deform::parseScene.
#include <cstddef>
#include <cstdint>

#include "fuzz_entry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  deform::fuzz::feedScene(std::string_view(reinterpret_cast<const char*>(data), size));
  return 0;
}
