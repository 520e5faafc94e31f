"""Tests of the Python module vdbclay, run by ctest with PYTHONPATH at the built module."""
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import unittest

import numpy as np
import vdbclay


def tmpdir():
    base = os.environ.get("VDBCLAY_TEST_TMP")
    if base:
        os.makedirs(base, exist_ok=True)
    return tempfile.mkdtemp(prefix="vdbclay-py-", dir=base)


class ShapesAndClay(unittest.TestCase):
    def test_box_clay_counts_and_masses_exactly(self):
        clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (3, 4, 5)), mass=700, threshold=1000)
        self.assertEqual(clay.voxel_count(), 4 * 5 * 6)
        self.assertEqual(clay.total_mass(), 4 * 5 * 6 * 700)
        self.assertEqual(clay.bounds, ([0, 0, 0], [3, 4, 5]))
        m = clay.mass_array()
        self.assertEqual(m.dtype, np.int32)
        self.assertEqual(m.shape, (4, 5, 6))
        self.assertTrue((m == 700).all())
        d = clay.density_array(min=(-1, 0, 0), max=(0, 0, 0))
        self.assertEqual(d.dtype, np.float32)
        self.assertEqual(d[0, 0, 0], 0.0)
        self.assertAlmostEqual(float(d[1, 0, 0]), 0.7, places=6)

    def test_shapes_have_signed_distances_and_move(self):
        s = vdbclay.sphere((0, 0, 0), 5)
        self.assertAlmostEqual(s.distance((0, 0, 0)), -5.0)
        self.assertAlmostEqual(s.distance((8, 0, 0)), 3.0)
        moved = s.moved(translate=(10, 0, 0))
        self.assertAlmostEqual(moved.distance((10, 0, 0)), -5.0)
        self.assertIn("sphere", repr(moved))
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.sphere((0, 0, 0), -1)
        self.assertIn("radius", str(e.exception))

    def test_numpy_round_trip_is_exact(self):
        rng = np.random.default_rng(7)
        a = rng.integers(0, 5000, size=(5, 6, 7)).astype(np.int32)
        clay = vdbclay.from_array(a, origin=(-2, 3, 1), threshold=1000)
        self.assertEqual(clay.total_mass(), int(a.sum()))
        b = clay.mass_array(min=(-2, 3, 1), max=(2, 8, 7))
        self.assertTrue(np.array_equal(a, b))
        with self.assertRaises(vdbclay.Error):
            vdbclay.from_array(np.full((2, 2, 2), -1), origin=(0, 0, 0))


class AutomatonTests(unittest.TestCase):
    def test_settle_conserves_mass_and_removes_overload(self):
        a = np.zeros((8, 8, 8), dtype=np.int32)
        a[:, 0:4, :] = 1000
        a[3, 4, 3] = 9000
        clay = vdbclay.from_array(a, threshold=1000)
        auto = vdbclay.Automaton(clay, rule="sorted", threads=2)
        r = auto.settle(max_steps=100000)
        self.assertTrue(r["settled"])
        self.assertEqual(r["residual_overload"], 0)
        self.assertEqual(auto.total_mass, int(a.sum()))
        self.assertEqual(clay.total_mass(), int(a.sum()))  # the same grid, changed in place
        self.assertLessEqual(int(clay.mass_array().max()), 1000)

    def test_threads_do_not_change_the_result(self):
        hashes = set()
        for threads in (1, 2, 3, 8):
            clay = vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 6), mass=1000)
            auto = vdbclay.Automaton(clay, threads=threads)
            auto.add_mass(np.full((2, 2, 2), 5000), origin=(0, 6, 0))
            r = auto.settle()
            hashes.add(clay.content_hash())
            # the passes' thread-seconds: some ran; none idle on one thread
            self.assertGreater(r["pass_busy_seconds"], 0.0)
            self.assertGreaterEqual(r["pass_idle_seconds"], 0.0)
            if threads == 1:
                self.assertEqual(r["pass_idle_seconds"], 0.0)
            del auto  # its thread limit ends with it, before the next one's begins
        self.assertEqual(len(hashes), 1)

    @unittest.skipUnless(hasattr(os, "fork"), "needs fork()")
    def test_a_forked_child_goes_on_with_the_automaton_and_gets_the_same_clay(self):
        # multiprocessing's "fork" start method: the child holds the parent's automaton, whose pass
        # threads stayed in the parent. It must settle (on threads of its own) to the same clay and
        # exit, without hanging or aborting when the automaton is destroyed there.
        clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (31, 31, 31)), mass=1000)
        auto = vdbclay.Automaton(clay, rule="prorata", threads=2)
        auto.add_mass(np.full((4, 4, 4), 3000, dtype=np.int32), origin=(14, 32, 14))
        auto.settle(max_steps=100000)
        auto.add_mass(np.full((4, 4, 4), 3000, dtype=np.int32), origin=(14, 36, 14))
        read_end, write_end = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: no unittest machinery, only its answer and exit code
            code = 1
            try:
                signal.alarm(120)  # a hang ends the child, which the parent reports
                os.close(read_end)
                auto.settle(max_steps=100000)
                answer = f"{clay.content_hash()} {clay.total_mass()}".encode()
                del auto
                os.write(write_end, answer)
                code = 0
            finally:
                os._exit(code)
        os.close(write_end)
        auto.settle(max_steps=100000)
        with os.fdopen(read_end, "rb") as f:
            answer = f.read().decode()
        _, status = os.waitpid(pid, 0)
        self.assertTrue(os.WIFEXITED(status), f"the child died: status {status}")
        self.assertEqual(os.WEXITSTATUS(status), 0)
        self.assertEqual(answer, f"{clay.content_hash()} {clay.total_mass()}")

    def test_add_mass_refuses_negative_results_and_changes_nothing(self):
        clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (1, 1, 1)), mass=10)
        auto = vdbclay.Automaton(clay)
        before = clay.content_hash()
        with self.assertRaises(vdbclay.Error):
            auto.add_mass(np.full((2, 2, 2), -11), origin=(0, 0, 0))
        self.assertEqual(clay.content_hash(), before)
        auto.add_mass(np.full((1, 1, 1), -10), origin=(0, 0, 0))
        self.assertEqual(clay.total_mass(), 70)

    def test_float_masses_are_whole_numbers_or_refused(self):
        # A float array holding whole numbers is taken as they are; 999.9 or 0.7 is refused, never
        # truncated, and a refused add_mass changes nothing.
        clay = vdbclay.from_array(np.full((2, 2, 2), 1000.0))
        self.assertEqual(clay.total_mass(), 8000)
        with self.assertRaisesRegex(vdbclay.Error, r"from_array: mass\[0, 0, 0\] is 999.9, not a whole number"):
            vdbclay.from_array(np.full((2, 2, 2), 999.9))
        with self.assertRaisesRegex(vdbclay.Error, r"mass\[1, 0, 1\] is nan"):
            a = np.zeros((2, 2, 2))
            a[1, 0, 1] = np.nan
            vdbclay.from_array(a)
        with self.assertRaisesRegex(vdbclay.Error, "expected an integer array, got dtype complex128"):
            vdbclay.from_array(np.zeros((2, 2, 2), dtype=complex))
        auto = vdbclay.Automaton(clay)
        before = clay.content_hash()
        with self.assertRaisesRegex(vdbclay.Error, r"add_mass: mass is 0.7, not a whole number"):
            auto.add_mass(0.7)
        with self.assertRaisesRegex(vdbclay.Error, r"add_mass: mass\[0, 1, 0\] is 0.5"):
            auto.add_mass(np.array([[[0.0], [0.5]]]))
        self.assertEqual(clay.content_hash(), before)
        auto.add_mass(np.full((1, 1, 1), 7.0), origin=(0, 0, 0))
        self.assertEqual(clay.total_mass(), 8007)

    def test_help_lists_the_classes(self):
        import pydoc
        self.assertIn("Clay", vdbclay.__all__)
        self.assertIn("Sculptor", vdbclay.__all__)
        self.assertNotIn("_vdbclay", vdbclay.__all__)
        text = pydoc.render_doc(vdbclay, renderer=pydoc.plaintext)
        for name in ("class Clay", "class Automaton", "class Sculptor", "from_array(", "make_clay("):
            self.assertIn(name, text)

    def test_push_moves_clay_out_of_a_tool_exactly(self):
        clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (15, 7, 15)), mass=1000)
        auto = vdbclay.Automaton(clay)
        r = auto.push([vdbclay.box((4, 5, 4), (11, 12, 11))])
        self.assertEqual(r["voxels_pushed"], 8 * 3 * 8)
        self.assertEqual(auto.total_mass, 16 * 8 * 16 * 1000)
        self.assertEqual(int(clay.mass_array(min=(4, 5, 4), max=(11, 7, 11)).sum()), 0)

    def test_deposit_carve_and_smooth_account_for_every_unit(self):
        clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (15, 7, 15)), mass=1000)
        auto = vdbclay.Automaton(clay)
        removed = auto.carve(vdbclay.box((4, 4, 4), (11, 12, 11)))
        self.assertEqual(removed, 8 * 4 * 8 * 1000)
        self.assertEqual(int(clay.mass_array(min=(4, 4, 4), max=(11, 7, 11)).sum()), 0)
        added = auto.deposit(vdbclay.box((0, 8, 0), (3, 9, 3)), mass=700)
        self.assertEqual(added, 4 * 2 * 4 * 700)
        self.assertEqual(auto.total_mass, 16 * 8 * 16 * 1000 - removed + added)
        before = auto.total_mass
        rough = auto.surface_energy((-2, -2, -2), (17, 12, 17))
        moved = auto.smooth(vdbclay.sphere((2, 8, 2), 4), strength=1.0)
        self.assertGreater(moved, 0)
        self.assertEqual(auto.total_mass, before)
        self.assertLess(auto.surface_energy((-2, -2, -2), (17, 12, 17)), rough)
        with self.assertRaises(vdbclay.Error):
            auto.smooth(vdbclay.sphere((2, 8, 2), 4), strength=2.0)

    def test_a_scene_with_add_and_remove_tools_reports_its_counts(self):
        scene = vdbclay.Scene.from_json(
            '{"clay": [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 1000}],'
            ' "tools": [{"shape": "sphere", "center": [0,14,6], "radius": 2, "action": "add",'
            '            "path": [{"translate": [1,0,0], "frames": 6}]},'
            '           {"shape": "sphere", "center": [6,12,6], "radius": 3, "action": "remove",'
            '            "path": [{"translate": [0,-1,0], "frames": 6}]}]}')
        self.assertEqual(scene.tool_actions, ["add", "remove"])
        s = vdbclay.Sculptor(scene, threads=2)
        frames = []
        report = s.run(progress=lambda r: frames.append((r["mass_added"], r["mass_removed"])))
        self.assertGreater(report["mass_added"], 0)
        self.assertGreater(report["mass_removed"], 0)
        self.assertEqual(report["mass_final"],
                         report["mass_initial"] + report["mass_added"] - report["mass_removed"])
        self.assertEqual(report["mass_drift"], 0)
        self.assertEqual(sum(a for a, _ in frames), report["mass_added"])
        self.assertEqual(sum(r for _, r in frames), report["mass_removed"])
        self.assertEqual(s.mass_added, report["mass_added"])
        self.assertEqual(s.mass_removed, report["mass_removed"])


def overloaded_lump(threads=2):
    """A cube at Tc with an overfull block on top: many steps of work for the automaton."""
    clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (15, 15, 15)), mass=1000)
    auto = vdbclay.Automaton(clay, rule="prorata", threads=threads)
    auto.add_mass(np.full((4, 4, 4), 30000, dtype=np.int32), origin=(6, 16, 6))
    return clay, auto


def endless_lump():
    """One 2D voxel of 2^31 - 1 at Tc 1000: it spreads for millions of steps (no call ends it soon)."""
    clay = vdbclay.from_array(np.full((1, 1, 1), 2**31 - 1), threshold=1000, dimensions=2)
    return clay, vdbclay.Automaton(clay, threads=2)


# A 48^3 cube at Tc pressed 3 voxels: thousands of steps over its 3 frames (about a second).
PRESSED_CUBE_AT_TC = json.dumps({
    "threshold": 1000,
    "clay": [{"shape": "box", "min": [0, 0, 0], "max": [47, 47, 47], "mass": 1000}],
    "tools": [{"shape": "box", "min": [-8, 48, -8], "max": [55, 56, 55],
               "path": [{"translate": [0, -1, 0], "frames": 3}]}],
    "obstacles": [{"shape": "box", "min": [-64, -4, -64], "max": [111, -1, 111]}],
    "settle": {"max_steps": 100000}})


def run_threads(*targets):
    """Runs each target on a thread of its own; returns the exceptions they raised."""
    errors = []

    def guarded(target):
        try:
            target()
        except BaseException as e:  # noqa: B902 - a thread's failure is the test's
            errors.append(e)

    threads = [threading.Thread(target=guarded, args=(t,)) for t in targets]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return errors


def interrupted(call):
    """Calls call() in the main thread while another thread sends this process SIGINT as soon as
    call() releases the GIL: the switch interval is raised so that the main thread keeps the GIL
    until the call itself lets it go, so the signal arrives inside the call, whatever the load.
    Returns the KeyboardInterrupt, or None when call() returned."""
    ready = threading.Event()

    def fire():
        ready.wait()
        os.kill(os.getpid(), signal.SIGINT)

    sender = threading.Thread(target=fire)
    old = sys.getswitchinterval()
    sender.start()
    sys.setswitchinterval(1000.0)
    try:
        ready.set()
        call()
        sender.join()  # a signal that came after the call returned raises here
        signal.getsignal(signal.SIGINT)
    except KeyboardInterrupt as e:
        return e
    finally:
        sys.setswitchinterval(old)
        sender.join()
    return None


class ThreadsAndInterrupts(unittest.TestCase):
    REPEATS = 3

    def test_two_threads_running_one_automaton_take_turns(self):
        steps = 150
        ref_clay, ref = overloaded_lump()
        ref.run(2 * steps)
        for _ in range(self.REPEATS):
            clay, auto = overloaded_lump()
            mass = auto.total_mass
            errors = run_threads(lambda: auto.run(steps), lambda: auto.run(steps))
            self.assertEqual(errors, [])
            self.assertEqual(auto.step_count, 2 * steps)
            self.assertEqual(auto.total_mass, mass)
            self.assertEqual(clay.total_mass(), mass)
            self.assertEqual(clay.content_hash(), ref_clay.content_hash())

    def test_reading_the_clay_while_another_thread_runs_sees_the_exact_mass(self):
        for _ in range(self.REPEATS):
            clay, auto = overloaded_lump()
            mass = auto.total_mass
            done = threading.Event()
            sums = []

            def run():
                try:
                    for _ in range(4):
                        auto.run(60)
                finally:
                    done.set()

            def read():
                while not done.is_set():
                    sums.append(int(clay.mass_array().sum(dtype=np.int64)))
                    sums.append(clay.total_mass())
                    sums.append(auto.clay.total_mass())
                    sums.append(auto.total_mass)
                sums.append(int(clay.mass_array().sum(dtype=np.int64)))

            self.assertEqual(run_threads(run, read), [])
            self.assertEqual(set(sums), {mass})
            self.assertEqual(auto.step_count, 240)

    def test_a_sculptor_read_from_another_thread_and_from_its_progress(self):
        scene = vdbclay.Scene.default()
        scene.frames = 2
        unbroken = vdbclay.Sculptor(scene, threads=2)
        unbroken.run()
        for _ in range(self.REPEATS):
            s = vdbclay.Sculptor(scene, threads=2)
            mass = s.total_mass
            done = threading.Event()
            seen = []

            def progress(report):
                seen.append(s.clay.total_mass())  # reading from inside the run is fine
                on_clay = vdbclay.Automaton(s.clay)
                with self.assertRaises(vdbclay.Error) as e:  # changing it is refused
                    on_clay.step()
                self.assertIn("progress callback or a signal handler", str(e.exception))

            def run():
                try:
                    s.run(progress=progress)
                finally:
                    done.set()

            def read():
                while not done.is_set():
                    seen.append(s.clay.total_mass())
                    seen.append(s.total_mass)
                    self.assertLessEqual(s.frame, 2)

            self.assertEqual(run_threads(run, read), [])
            self.assertEqual(set(seen), {mass})
            self.assertTrue(s.done)
            self.assertEqual(s.clay.content_hash(), unbroken.clay.content_hash())

    def test_two_automata_on_one_clay_stay_exact(self):
        # Each rescans the grid the other changed: their totals and overloads are the clay's.
        clay, first = overloaded_lump()
        mass = clay.total_mass()
        second = vdbclay.Automaton(clay, rule="prorata", threads=2)
        for _ in range(self.REPEATS):
            first.run(20)
            second.run(20)
            self.assertEqual(first.residual_overload, second.residual_overload)
            self.assertEqual(run_threads(lambda: first.run(30), lambda: second.run(30)), [])
            self.assertEqual(first.residual_overload, second.residual_overload)
            self.assertEqual(first.total_mass, mass)
            self.assertEqual(second.total_mass, mass)
        self.assertEqual(clay.total_mass(), mass)

    def test_ctrl_c_stops_settle_and_the_automaton_goes_on_exactly(self):
        clay, auto = endless_lump()
        e = interrupted(lambda: auto.settle(max_steps=10**9))
        self.assertIsInstance(e, KeyboardInterrupt)
        stopped_at = auto.step_count
        self.assertGreater(stopped_at, 0)
        self.assertEqual(auto.total_mass, 2**31 - 1)
        self.assertEqual(clay.total_mass(), 2**31 - 1)
        auto.run(10)
        ref_clay, ref = endless_lump()
        ref.run(stopped_at + 10)
        self.assertEqual(clay.content_hash(), ref_clay.content_hash())

    def test_ctrl_c_stops_run_between_two_steps(self):
        clay, auto = endless_lump()
        e = interrupted(lambda: auto.run(10**9))
        self.assertIsInstance(e, KeyboardInterrupt)
        stopped_at = auto.step_count
        self.assertLess(stopped_at, 10**9)
        self.assertEqual(clay.total_mass(), 2**31 - 1)
        ref_clay, ref = endless_lump()
        ref.run(stopped_at)
        self.assertEqual(clay.content_hash(), ref_clay.content_hash())

    def test_ctrl_c_stops_make_clay(self):
        # A plate one voxel thick turned 45 degrees: billions of voxel centres to test in its bounds.
        plate = vdbclay.box((0, 0, 0), (3000, 0, 3000)).moved(rotate=(45, 0, 0))
        e = interrupted(lambda: vdbclay.make_clay(plate, mass=1000, memory_budget="none"))
        self.assertIsInstance(e, KeyboardInterrupt)
        self.assertEqual(vdbclay.make_clay(vdbclay.box((0, 0, 0), (1, 1, 1)), mass=5).total_mass(), 40)

    def test_ctrl_c_stops_a_sculptor_which_then_finishes_as_an_unbroken_run(self):
        scene = vdbclay.Scene.from_json(PRESSED_CUBE_AT_TC)
        unbroken = vdbclay.Sculptor(scene, threads=2)
        unbroken.run()
        for _ in range(self.REPEATS):
            s = vdbclay.Sculptor(scene, threads=2)
            mass = s.total_mass
            e = interrupted(lambda: s.run())
            self.assertIsInstance(e, KeyboardInterrupt)
            self.assertEqual(s.total_mass, mass)
            self.assertEqual(s.clay.total_mass(), mass)
            s.run()
            self.assertTrue(s.done)
            self.assertEqual(s.clay.content_hash(), unbroken.clay.content_hash())
            self.assertEqual(s.clay.steps, unbroken.clay.steps)


class MemoryBudget(unittest.TestCase):
    def tearDown(self):
        vdbclay.set_memory_budget(None)

    def test_a_huge_shape_is_refused_before_any_voxel_is_made(self):
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 1e6), 1000)
        self.assertIn("more than the memory budget", str(e.exception))

    def test_the_module_budget_round_trips_and_holds_for_every_call(self):
        default = vdbclay.memory_budget()
        self.assertGreater(default, 0)
        self.assertNotEqual(default, vdbclay.NO_MEMORY_BUDGET)
        vdbclay.set_memory_budget("512M")
        self.assertEqual(vdbclay.memory_budget(), 512 << 20)
        vdbclay.set_memory_budget(3 << 30)
        self.assertEqual(vdbclay.memory_budget(), 3 << 30)
        vdbclay.set_memory_budget("none")
        self.assertEqual(vdbclay.memory_budget(), vdbclay.NO_MEMORY_BUDGET)
        for bad in ("lots", 0, -1, 1.5):
            with self.assertRaises(vdbclay.Error):
                vdbclay.set_memory_budget(bad)
        self.assertEqual(vdbclay.memory_budget(), vdbclay.NO_MEMORY_BUDGET)
        vdbclay.set_memory_budget(None)
        self.assertEqual(vdbclay.memory_budget(), default)

        vdbclay.set_memory_budget("1M")
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.Sculptor(vdbclay.Scene.default())
        self.assertIn("more than the memory budget of 1.00 MiB", str(e.exception))
        scene = vdbclay.Scene.default()
        scene.memory_budget = "none"  # the module's budget replaces the scene's, as --memory-budget
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.Sculptor(scene)
        self.assertIn("more than the memory budget of 1.00 MiB", str(e.exception))
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 3000), mass=800)
        self.assertIn("more than the memory budget of 1.00 MiB", str(e.exception))
        self.assertEqual(vdbclay.Sculptor(scene, memory_budget="none").memory_budget,
                         vdbclay.NO_MEMORY_BUDGET)  # a call's own budget wins
        self.assertEqual(vdbclay.Scene.from_json("{}").memory_budget, 1 << 20)


class FilesAndScenes(unittest.TestCase):
    def test_write_read_round_trip_keeps_clay_and_metadata(self):
        d = tmpdir()
        clay = vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 4), mass=250, threshold=250, voxel_size=0.5)
        path = os.path.join(d, "ball.vdb")
        clay.write(path)
        back = vdbclay.read(path)
        self.assertEqual(back.content_hash(), clay.content_hash())
        self.assertEqual(back.threshold, 250)
        self.assertEqual(back.voxel_size, 0.5)
        self.assertIn("vdbclay_threshold", vdbclay.describe(path))
        mesh = os.path.join(d, "ball.obj")
        back.write_mesh(mesh)
        with open(mesh) as f:
            self.assertTrue(f.read().startswith("# vdbclay"))
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.read(os.path.join(d, "missing.vdb"))
        self.assertIn("missing.vdb", str(e.exception))

    def test_write_holds_the_grids_named(self):
        d = tmpdir()
        clay = vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 4), mass=250, threshold=250)
        fog = os.path.join(d, "fog.vdb")
        clay.write(fog, grids=["density"])
        grids = [l for l in vdbclay.describe(fog).splitlines() if l.startswith("grid ")]
        self.assertEqual(len(grids), 1, grids)
        self.assertTrue(grids[0].startswith('grid "density"'), grids)
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.read(fog)
        self.assertIn('has no grid named "mass"', str(e.exception))
        both = os.path.join(d, "both.vdb")
        clay.write(both, grids=["surface", "mass"])
        self.assertEqual(vdbclay.read(both).content_hash(), clay.content_hash())
        for bad, needle in ((["fog"], '"fog" is not a grid of a clay file'), ([], "at least one"),
                            (["mass", "mass"], 'grid "mass" is named twice')):
            with self.assertRaises(vdbclay.Error) as e:
                clay.write(os.path.join(d, "bad.vdb"), grids=bad)
            self.assertIn(needle, str(e.exception))
        self.assertFalse(os.path.exists(os.path.join(d, "bad.vdb")))

    def test_mesh_clay_keeps_the_volume_of_a_mesh_written_to_keep_it(self):
        d = tmpdir()
        clay = vdbclay.make_clay(vdbclay.box((0, 0, 0), (9, 5, 7)), mass=1000, voxel_size=0.5, up="z")
        mesh = os.path.join(d, "box.obj")
        clay.write_mesh(mesh, keep_volume=True)
        back = vdbclay.make_clay(vdbclay.mesh(mesh, voxel_size=0.5, up="z"), mass=1000)
        self.assertAlmostEqual(back.total_mass() / 1000, 10 * 6 * 8, delta=0.005 * 480)
        clay.write_mesh(mesh)  # marching cubes cuts the box's edges
        self.assertLess(vdbclay.make_clay(vdbclay.mesh(mesh, voxel_size=0.5, up="z"), mass=1000).total_mass(),
                        0.99 * 480000)

    def test_scene_runs_frame_by_frame_with_progress_and_continues_from_its_file(self):
        d = tmpdir()
        scene = vdbclay.Scene.default()
        scene.frames = 4
        unbroken = vdbclay.Sculptor(scene, threads=2)
        initial = unbroken.total_mass
        self.assertGreater(initial, 0)
        seen = []
        report = unbroken.run(progress=lambda r: seen.append((r["frame"], r["total_frames"])))
        self.assertEqual(report["frames"], 4)
        self.assertEqual(report["mass_initial"], initial)
        self.assertEqual(report["mass_drift"], 0)
        self.assertEqual(report["content_hash"], f"{unbroken.clay.content_hash():016x}")
        self.assertEqual(seen, [(1, 4), (2, 4), (3, 4), (4, 4)])
        self.assertEqual(unbroken.total_mass, initial)

        first = vdbclay.Sculptor(scene, threads=1)
        self.assertEqual(first.run(frames=2)["frames"], 2)
        path = os.path.join(d, "half.vdb")
        first.write(path)
        scene.start = path
        second = vdbclay.Sculptor(scene, threads=2)
        self.assertEqual(second.frame, 2)
        second.run_frame()
        second.run(progress=lambda r: None)
        self.assertTrue(second.done)
        self.assertEqual(second.clay.content_hash(), unbroken.clay.content_hash())

    def test_progress_returning_false_stops(self):
        scene = vdbclay.Scene.default()
        s = vdbclay.Sculptor(scene)
        self.assertEqual(s.run(progress=lambda r: False)["frames"], 1)
        self.assertEqual(s.frame, 1)
        self.assertTrue(s.stopped)
        self.assertFalse(s.frame_open)

    def test_an_error_in_progress_reaches_the_caller_and_the_run_goes_on_after(self):
        s = vdbclay.Sculptor(vdbclay.Scene.default())

        def fail(report):
            raise ValueError("from progress")

        with self.assertRaises(ValueError):
            s.run(progress=fail)
        self.assertEqual(s.frame, 1)
        self.assertEqual(s.run()["frames"], s.total_frames - 1)
        self.assertTrue(s.done)

    @unittest.skipUnless(os.environ.get("VDBCLAY_CLI"), "needs the vdbclay command (VDBCLAY_CLI)")
    def test_run_report_is_the_cli_stats(self):
        d = tmpdir()
        stats = os.path.join(d, "stats.json")
        subprocess.run([os.environ["VDBCLAY_CLI"], "run", "--frames", "2", "--threads", "2", "--quiet",
                        "--stats", stats], check=True, stdout=subprocess.DEVNULL)
        with open(stats) as f:
            cli = json.load(f)
        report = vdbclay.Sculptor(vdbclay.Scene.default(), threads=2).run(frames=2)
        self.assertEqual(sorted(report), sorted(cli))
        timed = {"seconds", "frame_seconds", "push_seconds", "setup_seconds", "output_seconds",
                 "transport_seconds", "stage_seconds", "pass_busy_seconds", "pass_idle_seconds", "heap"}
        for key in cli:
            if key not in timed:
                self.assertEqual(report[key], cli[key], key)
        self.assertEqual(sorted(report["stage_seconds"]), sorted(cli["stage_seconds"]))
        self.assertEqual(len(report["frame_seconds"]), 2)
        self.assertEqual(len(cli["frame_seconds"]), 2)
        self.assertEqual(report["output_seconds"], 0)
        self.assertGreater(report["setup_seconds"], 0)

    def test_memory_budget_refuses_a_scene_and_stops_a_run_that_outgrows_it(self):
        d = tmpdir()
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.Sculptor(vdbclay.Scene.default(), memory_budget="1M")
        self.assertIn("more than the memory budget of 1.00 MiB", str(e.exception))
        scene = vdbclay.Scene.default()
        scene.memory_budget = "none"
        self.assertEqual(scene.memory_budget, vdbclay.NO_MEMORY_BUDGET)
        self.assertEqual(vdbclay.Sculptor(scene).memory_budget, vdbclay.NO_MEMORY_BUDGET)
        scene.memory_budget = None
        self.assertEqual(scene.memory_budget, 0)
        self.assertGreater(vdbclay.Sculptor(scene).memory_budget, 0)  # the default, resolved
        with self.assertRaises(vdbclay.Error):
            scene.memory_budget = "lots"
        with self.assertRaises(vdbclay.Error) as e:  # as `vdbclay import` checks it
            vdbclay.make_clay(vdbclay.sphere((0, 0, 0), 3000), mass=800, memory_budget="1G")
        self.assertIn("more than the memory budget of 1.00 GiB", str(e.exception))

        # Clay at 2^31 - 1 per voxel spreads far beyond what the estimate sees in its file: the
        # run stops once its grids outgrow the budget, and write() saves where it stopped.
        dense = vdbclay.make_clay(vdbclay.box((0, 0, 0), (2, 2, 0)), mass=2**31 - 1, dimensions=2)
        dense.write(os.path.join(d, "dense.vdb"))
        text = ('{"dimensions": 2, "settle": {"max_steps": 160}, '
                '"clay": [{"shape": "vdb", "file": "dense.vdb"}]}')
        scene = vdbclay.Scene.from_json(text, base_dir=d, memory_budget="56M")  # 48 MiB: the program
        self.assertEqual(scene.memory_budget, 56 << 20)
        s = vdbclay.Sculptor(scene, threads=2)
        with self.assertRaises(vdbclay.Error) as e:
            s.run()
        self.assertIn("the clay outgrew the memory budget of 56.0 MiB", str(e.exception))
        self.assertTrue(s.stopped)
        self.assertTrue(s.frame_open)
        checkpoint = os.path.join(d, "dense-checkpoint.vdb")
        s.write(checkpoint)
        self.assertEqual(vdbclay.read(checkpoint).total_mass(), dense.total_mass())

    def test_bad_scene_is_an_error_naming_the_field(self):
        with self.assertRaises(vdbclay.Error) as e:
            vdbclay.Scene.from_json('{"threshold": -5}', source="bad.json")
        self.assertIn("bad.json", str(e.exception))
        self.assertIn("threshold", str(e.exception))


if __name__ == "__main__":
    unittest.main()
