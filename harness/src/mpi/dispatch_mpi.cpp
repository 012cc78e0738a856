// The MPI dispatcher (see dispatch.h): rank 0 hands out tasks, one at a time, to idle workers.
//
// Messages (MPI_COMM_WORLD): rank 0 -> worker: kTask {"id", "task"} or kStop; worker -> rank 0:
// kBeat (empty, every second while a task runs) and kResult {"id", "result"}. A worker runs its
// task in a thread (the task forks its `deformbench run` children; only the worker's main
// thread calls MPI) and keeps beating meanwhile, so a worker silent for longer than the limit is
// dead, not slow. Open MPI aborts the whole job when a rank dies unless mpirun has
// --enable-recovery; with it rank 0 carries on: the lost worker's task goes once to another
// worker, and the children of the dead worker die with it (PR_SET_PDEATHSIG, child_process.cpp).
#include <deform_harness/dispatch.h>
#include <mpi.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <map>
#include <set>
#include <thread>

namespace deform::harness {

using ojson = nlohmann::ordered_json;

namespace {

enum Tag : int { kTask = 1, kStop = 2, kResult = 3, kBeat = 4 };
using Clock = std::chrono::steady_clock;

bool g_started = false;
int g_rank = 0, g_size = 1;
double g_lostAfterS = 30;
std::set<int> g_dead;  // workers taken as dead (never used again)

void sendText(const std::string& s, int dest, int tag) {
  MPI_Send(s.data(), int(s.size()), MPI_CHAR, dest, tag, MPI_COMM_WORLD);
}

std::string receive(const MPI_Status& probed) {
  int n = 0;
  MPI_Get_count(&probed, MPI_CHAR, &n);
  std::string s(size_t(n), '\0');
  MPI_Recv(s.data(), n, MPI_CHAR, probed.MPI_SOURCE, probed.MPI_TAG, MPI_COMM_WORLD,
           MPI_STATUS_IGNORE);
  return s;
}

ojson executeCaught(const ojson& task) {
  try {
    return executeTask(task);
  } catch (const std::exception& e) {
    return lostTaskResult(task, std::string("worker error: ") + e.what());
  }
}

int workerLoop() {
  for (;;) {
    MPI_Status st;
    MPI_Probe(0, MPI_ANY_TAG, MPI_COMM_WORLD, &st);
    const std::string text = receive(st);
    if (st.MPI_TAG == kStop) {
      if (text == "exit") {  // a rank was lost: MPI_Finalize would wait for it forever
        std::fflush(nullptr);
        std::_Exit(0);
      }
      return 0;
    }
    if (st.MPI_TAG != kTask) continue;
    const ojson msg = ojson::parse(text);
    std::atomic<bool> done{false};
    ojson result;
    std::thread t([&] {
      result = executeCaught(msg.at("task"));
      done = true;
    });
    auto lastBeat = Clock::now();
    while (!done) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      if (Clock::now() - lastBeat >= std::chrono::seconds(1)) {
        sendText("", 0, kBeat);
        lastBeat = Clock::now();
      }
    }
    t.join();
    sendText(ojson({{"id", msg.at("id")}, {"result", result}}).dump(), 0, kResult);
  }
}

class MpiDispatcher : public Dispatcher {
 public:
  explicit MpiDispatcher(std::function<void(const std::string&)> note) : m_note(std::move(note)) {}
  int width() const override { return std::max(1, g_size - 1 - int(g_dead.size())); }

  void run(const std::vector<ojson>& tasks, const std::function<void(size_t)>& onStart,
           const std::function<void(size_t, const ojson&)>& onDone) override {
    const std::vector<size_t> pending = tasksToRun(tasks, onDone);
    for (const std::vector<size_t>& stage : byStage(tasks, pending))
      runStage(tasks, std::deque<size_t>(stage.begin(), stage.end()), onStart, onDone);
  }

 private:
  void runStage(const std::vector<ojson>& tasks, std::deque<size_t> todo,
                const std::function<void(size_t)>& onStart,
                const std::function<void(size_t, const ojson&)>& onDone) {
    struct Busy {
      size_t task;
      Clock::time_point lastSeen;
    };
    std::map<int, Busy> busy;  // worker rank -> its task
    std::map<size_t, int> attempts;
    const auto alive = [&] {
      std::vector<int> w;
      for (int r = 1; r < g_size; ++r)
        if (!g_dead.count(r)) w.push_back(r);
      return w;
    };
    while (!todo.empty() || !busy.empty()) {
      const std::vector<int> workers = alive();
      for (int w : workers) {
        if (todo.empty()) break;
        if (busy.count(w)) continue;
        const size_t i = todo.front();
        todo.pop_front();
        if (attempts[i]++ == 0 && onStart) onStart(i);
        sendText(ojson({{"id", i}, {"task", tasks[i]}}).dump(), w, kTask);
        busy[w] = {i, Clock::now()};
      }
      if (workers.empty() && !todo.empty()) {  // nobody left: run it here
        const size_t i = todo.front();
        todo.pop_front();
        if (attempts[i]++ == 0 && onStart) onStart(i);
        const ojson r = executeCaught(tasks[i]);
        if (onDone) onDone(i, r);
        continue;
      }
      int flag = 0;
      MPI_Status st;
      MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st);
      if (flag) {
        const std::string text = receive(st);
        const int w = st.MPI_SOURCE;
        if (g_dead.count(w) || !busy.count(w)) continue;  // late word from a worker given up
        busy[w].lastSeen = Clock::now();
        if (st.MPI_TAG == kResult) {
          const ojson msg = ojson::parse(text);
          const size_t i = msg.at("id").get<size_t>();
          if (i != busy[w].task) continue;
          busy.erase(w);
          if (onDone) onDone(i, msg.at("result"));
        }
        continue;
      }
      const auto now = Clock::now();
      for (auto it = busy.begin(); it != busy.end();) {
        const double silent = std::chrono::duration<double>(now - it->second.lastSeen).count();
        if (silent <= g_lostAfterS) {
          ++it;
          continue;
        }
        const int w = it->first;
        const size_t i = it->second.task;
        g_dead.insert(w);
        it = busy.erase(it);
        const std::string id = tasks[i].value("out", tasks[i].value("log", std::to_string(i)));
        if (attempts[i] < 2) {
          if (m_note)
            m_note("mpi: worker rank " + std::to_string(w) + " lost (silent " +
                   std::to_string(int(silent)) + " s); its case " + id + " goes to another worker");
          todo.push_front(i);
        } else {
          if (m_note)
            m_note("mpi: worker rank " + std::to_string(w) + " lost; case " + id +
                   " lost twice, recorded failed");
          if (onDone) onDone(i, lostTaskResult(tasks[i], "worker process lost twice (mpi)"));
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }

  std::function<void(const std::string&)> m_note;
};

}  // namespace

bool mpiAvailable() {
  return true;
}

bool mpiStart(int& argc, char**& argv, double lostAfterS, int& exitCode) {
  exitCode = 0;
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
  g_lostAfterS = lostAfterS;
  g_started = true;
  if (g_rank == 0) return true;
  exitCode = workerLoop();
  MPI_Finalize();
  g_started = false;
  return false;
}

void mpiStop(int exitCode) {
  if (!g_started) return;
  g_started = false;
  // With a lost rank, MPI_Finalize would wait for it forever: every live rank leaves without it
  // (mpirun --enable-recovery accepts that).
  const bool lost = !g_dead.empty();
  if (g_rank == 0)
    for (int r = 1; r < g_size; ++r)
      if (!g_dead.count(r)) sendText(lost ? "exit" : "", r, kStop);
  if (lost) {
    std::fflush(nullptr);
    std::_Exit(exitCode);
  }
  MPI_Finalize();
}

std::unique_ptr<Dispatcher> mpiDispatcher(const std::function<void(const std::string&)>& note) {
  if (!g_started) return localDispatcher(1);
  return std::make_unique<MpiDispatcher>(note);
}

}  // namespace deform::harness
