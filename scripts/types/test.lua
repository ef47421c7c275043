---@meta _
-- LuaLS annotations of the vmac test API (docs/TESTING.md): the globals a
-- *_test.lua file gets from core/vtest/runner.lua, and the board object.
-- Declarations only. Test files run in plain LuaJIT, not in the sandbox.

---The spec of board{}.
---@class vmac.test.BoardSpec
---@field name string the board's name
---@field plant "washer"|"dishwasher"|"lights"|"generic" the simulated plant (docs/BOARD.md)
---@field driver? string the driver the board announces (default: the plant's name)
---@field major? integer for machines of several boards
---@field minor? integer
---@field params? table<string, vmac.Value> driver params (driver.NAME.param.KEY)
---@field clock? vmac.test.ClockSpec the board's oscillator (default: a perfect one)

---A board's oscillator (TESTING.md, "Board clocks"); every field defaults to 0.
---@class vmac.test.ClockSpec
---@field ppm? number the counter runs fast by this much (negative: slow), -1000..1000
---@field offset? number seconds: counter minus host time at the test's time 0, -900..900
---@field jitter? number seconds: mean of the receive stamp's exponential delay (20e-6: 20 us), 0..0.01
---@field wander? number ppm/sqrt(s): the drift's random walk (0.02: a poor crystal)

---A board's clock now (b.clock): what the board's disciplined clock says, and the truth.
---@class vmac.test.Clock
---@field state "unsynced"|"locking"|"locked"|"holdover"|"lost"
---@field offset? number seconds: the board's estimate of its counter minus host time (nil: unsynced, lost)
---@field bound? number seconds: its error bound now
---@field error? number seconds: its reading of host time less the true one (less the wire's 50 us)
---@field drift_ppm? number the drift it learnt (nil: unsynced)
---@field true_ppm number the counter's true drift now
---@field syncs integer SYNC samples fed to it
---@field output? vmac.test.TimedOutput its last output change of time-triggered I/O (nil: none yet)

---A board's output change of time-triggered I/O (b.clock.output).
---@class vmac.test.TimedOutput
---@field time number virtual seconds it happened at (the truth)
---@field asked number the host instant its frame asked for, seconds
---@field how "instant"|"arrival"|"late"|"overrun"
---@field count integer output changes of time-triggered I/O so far

---A host event, as GET /api/status gives it.
---@class vmac.test.Event
---@field time number virtual seconds
---@field kind string attached, dropped, driver_error, sleeping, ...
---@field device string
---@field text string

---What events() and expect_event() match: a kind, or fields (text: a plain substring).
---@alias vmac.test.EventFilter string|{kind?: string, device?: string, text?: string}

---One service of a board, as the board saw it.
---@class vmac.test.Service
---@field time number
---@field io table<string, boolean|number>

---Wire faults on a board's frames, both ways.
---@class vmac.test.Faults
---@field drop? number probability
---@field corrupt? number probability (one byte flipped)
---@field delay? number seconds added to a fraction of frames
---@field delay_fraction? number default 1
---@field late? number seconds added to every reply

---A mock board (TESTING.md, "A board object").
---@class vmac.test.Board
---@field name string
---@field state "attaching"|"running"|"errant"|"sleeping"|"waiting"|"absent" the host's state of the device
---@field device table? the device's status as GET /api/status gives it
---@field io table<string, boolean|number> the named I/O as the board sees it (read-only)
---@field inp table<string, boolean|number> the same as io
---@field out table<string, boolean|number> the same as io
---@field var table<string, vmac.Value|nil> the driver's published variables
---@field plant table<string, number|boolean> the plant's true state
---@field clock vmac.test.Clock the board's clock now
local Board = {}

---An operator action on the plant (value default 1); fails the test when unknown or out of range.
---@param action string
---@param value? number
function Board:set(action, value) end

---As set, returning false instead of failing.
---@param action string
---@param value? number
---@return boolean
function Board:try_set(action, value) end

---set(name, 1)
---@param name string
function Board:press(name) end

---set(name, 0)
---@param name string
function Board:release(name) end

---set("door", 0)
function Board:open_door() end

---set("door", 1)
function Board:close_door() end

---Operator input to the driver: a command or a settable variable; fails the test when refused.
---@param name string
---@param value? vmac.Value
---@return string reply
function Board:input(name, value) end

---As input, returning ok, reply.
---@param name string
---@param value? vmac.Value
---@return boolean ok
---@return string reply
function Board:try_input(name, value) end

---Pull the cable: frames both ways are lost.
function Board:unplug() end

---Put the cable back.
function Board:replug() end

---The board stops, outputs off.
function Board:power_off() end

---The board starts from its reset state and announces itself again.
function Board:power_on() end

---Wire faults on this board's frames; faults{} clears them.
---@param spec vmac.test.Faults
function Board:faults(spec) end

---A step of the board's drift by ppm from now on (a change of temperature).
---@param ppm number
function Board:clock_step(ppm) end

---The board's last services (up to 32), oldest first.
---@return vmac.test.Service[]
function Board:history() end

---A condition declared with always().
---@class vmac.test.Always
---@field what string
---@field where string where it was declared

---Declare a test; it runs in a new virtual world at time 0.
---@param name string
---@param fn fun()
function test(name, fn) end

---Plug in a mock board.
---@param spec vmac.test.BoardSpec
---@return vmac.test.Board
function board(spec) end

---The demo kitchen: washer-1, dishwasher-1 and lights-1.
---@param spec? {params?: {washer?: table, dishwasher?: table, lights?: table}}
---@return {washer: vmac.test.Board, dishwasher: vmac.test.Board, lights: vmac.test.Board}
function kitchen(spec) end

---Host settings (docs/HOST.md keys); before the first board of a test.
---@param settings table<string, any>
function config(settings) end

---Every call of driver name takes that much virtual time.
---@param name string
---@param seconds number
function driver_cost(name, seconds) end

---Stop the host as SIGTERM does.
function stop_host() end

---The host dies at once, as with SIGKILL or a power cut.
function crash_host() end

---After crash_host(): a new host with the same settings.
function start_host() end

---Replay a flight recording's text against the driver under test.
---@param text string
---@return string report
function replay(text) end

---Advance virtual time.
---@param seconds number
function run_for(seconds) end

---Advance until cond() is true; fail with what after timeout virtual seconds.
---@param cond fun(): any
---@param timeout number seconds
---@param what? string
---@return number seconds it took
function run_until(cond, timeout, what) end

---run_until, read as an expectation.
---@param cond fun(): any
---@param within number seconds
---@param what? string
---@return number seconds it took
function eventually(cond, within, what) end

---From now to the end of the test, cond() must hold at every check; with
---within, it may be false for at most that long at a time.
---@param what string
---@param cond fun(): any
---@param options? {within?: number|string} within: seconds, or "N periods" of the boards' service period
---@return vmac.test.Always
function always(what, cond, options) end

---What every() returns.
---@class vmac.test.Every
local Every = {}

---fn is called no more (also from inside fn).
function Every:stop() end

---fn(t) every seconds (> 0) of virtual time from now, while the test runs
---the clock (run_for, run_until, eventually); fn may not run the clock itself.
---@param seconds number
---@param fn fun(t: number)
---@return vmac.test.Every
function every(seconds, fn) end

---Virtual seconds since the test began.
---@return number
function now() end

---Fails unless value is truthy.
---@param value any
---@param what? string
function expect(value, what) end

---Fails unless actual == expected.
---@param actual any
---@param expected any
---@param what? string
function expect_eq(actual, expected, what) end

---Fails unless |actual - expected| <= tolerance.
---@param actual number
---@param expected number
---@param tolerance number
---@param what? string
function expect_near(actual, expected, tolerance, what) end

---Fails unless an event matches filter; returns it.
---@param filter vmac.test.EventFilter
---@param what? string
---@return vmac.test.Event
function expect_event(filter, what) end

---The events matching filter (all without one).
---@param filter? {kind?: string, device?: string, text?: string}
---@return vmac.test.Event[]
function events(filter) end

---Always fails.
---@param message string
function fail(message) end
