// deformbench harness: progress of long commands (tables, sweep, stability, bench): cases done
// out of the total, elapsed time and an estimate of the time remaining (elapsed / done * left).
// On a terminal one line is rewritten in place; when the stream is not a terminal, or CI=true,
// or DEFORM_PROGRESS=plain, every update is a plain line of its own.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace deform::harness {

class Progress {
 public:
  /// total: number of cases; what: a few words ("tables", "stability") prefixed to each line.
  /// stream: where to write (stderr by default, so stdout stays the command's result).
  Progress(int total, std::string what, std::FILE* stream = stderr);
  ~Progress();  // ends a live line with a newline

  /// A case starts (shown on a live line; also printed as a plain line when not live).
  void start(const std::string& label);
  /// A case ended; result is a short word ("ok", "failed", "skipped").
  void finish(const std::string& label, const std::string& result);
  /// Adds to the total (cases discovered late).
  void addTotal(int n) { m_total += n; }

  int done() const { return m_done; }
  bool live() const { return m_live; }
  /// "3/10  1m05s elapsed  ~2m31s left" (the estimate is omitted until one case finished).
  std::string status() const;

  /// "1h02m", "3m05s", "12.3s".
  static std::string formatSeconds(double s);

 private:
  void emit(const std::string& line, bool permanent);
  int m_total;
  int m_done = 0;
  std::string m_what;
  std::FILE* m_stream;
  bool m_live = false;
  size_t m_lastWidth = 0;
  std::chrono::steady_clock::time_point m_start;
};

}  // namespace deform::harness
