// Fixture: deform_register dies of SIGSEGV (the loader probes registration in a child process,
// so this is a PluginError naming the signal, not the end of the program).
#include <deform/sdk/registry.h>

#include <csignal>

DEFORM_PLUGIN(registry) {
  (void)registry;
  std::raise(SIGSEGV);
}
