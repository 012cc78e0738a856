// Prints the `metaballs-construction` table (paper Table 1 beside ours) as JSON:
//   metaballs_table [OUT.json]
#include "metaballs_table.h"

#include <deform/cache.h>
#include <deform/model.h>

#include <exception>
#include <iostream>

namespace deform {}  // namespace deform

int main(int argc, char** argv) {
  try {
    const std::string text = deform::metaballs::metaballsConstructionTable().dump(2) + "\n";
    if (argc > 1)
      deform::writeFileAtomic(argv[1], text);
    else
      std::cout << text;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "metaballs_table: " << e.what() << "\n";
    return 1;
  }
}
