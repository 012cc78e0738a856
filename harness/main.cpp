// deformbench: the command-line program (verbs: plugins, run, phantom, ...). Skeleton; the verbs
// are filled in by the harness work.
#include <cstdio>

int main() {
  std::puts("deformbench: skeleton");
  return 0;
}
