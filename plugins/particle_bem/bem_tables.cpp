// bem_tables: writes the data of the paper's Tables 1 and 2 (bem-timing, bem-accuracy) as JSON.
// Usage: bem_tables [timing|accuracy|all] [--out FILE] [--quick]
#include "paper_tables.h"

#include <cstring>
#include <fstream>
#include <iostream>

int main(int argc, char** argv) {
  std::string which = "all", out;
  deform::particle_bem::TableOptions o;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--out") && i + 1 < argc) {
      out = argv[++i];
    } else if (!std::strcmp(argv[i], "--quick")) {
      o.quick = true;
    } else if (!std::strcmp(argv[i], "timing") || !std::strcmp(argv[i], "accuracy") ||
               !std::strcmp(argv[i], "all")) {
      which = argv[i];
    } else {
      std::cerr << "usage: bem_tables [timing|accuracy|all] [--out FILE] [--quick]\n";
      return 2;
    }
  }
  try {
    nlohmann::json j = nlohmann::json::array();
    if (which != "accuracy") j.push_back(deform::particle_bem::bemTimingTable(o));
    if (which != "timing") j.push_back(deform::particle_bem::bemAccuracyTable(o));
    if (out.empty()) {
      std::cout << j.dump(2) << "\n";
    } else {
      std::ofstream f(out);
      f << j.dump(2) << "\n";
      if (!f) {
        std::cerr << out << ": cannot write\n";
        return 1;
      }
    }
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 1;
  }
  return 0;
}
