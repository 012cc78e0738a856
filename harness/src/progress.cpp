// Progress lines for long commands (see progress.h).
#include <deform_harness/progress.h>

#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>

namespace deform::harness {

namespace {

bool plainRequested() {
  const char* ci = std::getenv("CI");
  if (ci && (std::strcmp(ci, "true") == 0 || std::strcmp(ci, "1") == 0)) return true;
  const char* mode = std::getenv("DEFORM_PROGRESS");
  return mode && std::strcmp(mode, "plain") == 0;
}

}  // namespace

Progress::Progress(int total, std::string what, std::FILE* stream)
    : m_total(total),
      m_what(std::move(what)),
      m_stream(stream),
      m_start(std::chrono::steady_clock::now()) {
  m_live = stream && isatty(fileno(stream)) && !plainRequested();
}

Progress::~Progress() {
  if (m_live && m_lastWidth > 0) {
    std::fputc('\n', m_stream);
    std::fflush(m_stream);
  }
}

std::string Progress::formatSeconds(double s) {
  char buf[32];
  if (!std::isfinite(s) || s < 0) return "?";
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  } else if (s < 3600) {
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  } else {
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  }
  return buf;
}

std::string Progress::status() const {
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
  std::string s = std::to_string(m_done) + "/" + std::to_string(m_total) + "  " +
                  formatSeconds(elapsed) + " elapsed";
  if (m_done > 0 && m_total > m_done)
    s += "  ~" + formatSeconds(elapsed / m_done * (m_total - m_done)) + " left";
  return s;
}

void Progress::emit(const std::string& line, bool permanent) {
  if (!m_stream) return;
  if (m_live) {
    std::string text = line;
    const size_t width = text.size();
    if (width < m_lastWidth) text.append(m_lastWidth - width, ' ');
    std::fprintf(m_stream, "\r%s", text.c_str());
    m_lastWidth = width;
    if (permanent) {
      std::fputc('\n', m_stream);
      m_lastWidth = 0;
    }
  } else {
    std::fprintf(m_stream, "%s\n", line.c_str());
  }
  std::fflush(m_stream);
}

void Progress::start(const std::string& label) {
  emit("[" + m_what + " " + status() + "] " + label + " ...", false);
}

void Progress::finish(const std::string& label, const std::string& result) {
  ++m_done;
  // A finished case stays on screen (one line each); the live line is then redrawn by start().
  emit("[" + m_what + " " + status() + "] " + label + ": " + result, true);
}

}  // namespace deform::harness
