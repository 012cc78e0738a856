// Placeholder so the harness library has a translation unit until the runner lands.
namespace deform::harness {}
