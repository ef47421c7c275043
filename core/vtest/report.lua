-- vmac test's reports (core/vtest/runner.lua runs the tests): what a
-- failed test shows (each board's last services among the test's
-- actions, the host's events), the human and TAP lines of each result,
-- and the JUnit XML. Formats: docs/TESTING.md.
local M = {}

-- The lines of traceback tb that are in the test file: where a failure
-- came from, innermost first.
function M.test_frames(tb, file)
	local out = {}
	for line in tb:gmatch("[^\n]+") do
		if line:find(file, 1, true) and not line:find("^%S") then out[#out + 1] = line:gsub("^%s+", "") end
	end
	return out
end

local function fmt_value(v)
	if v == true then return "1" elseif v == false then return "0" end
	if type(v) == "number" then return string.format("%.4g", v) end
	return tostring(v)
end

-- A board's last services (--history) as it saw them, and in time among
-- them what the test did to it or to the host: the latest such action
-- before the first row shown too, so the cause is in view. The first
-- service after an action is marked `*`: it is the first the board's view
-- (and the driver) can show of it.
local function services_and_actions(current, history, h, board_name, period_us)
	local first = math.max(1, #h - history + 1)
	if #h == 0 or history <= 0 then return {} end
	local from_t = h[first].time
	local acts, before = {}, nil
	for _, a in ipairs(current.actions) do
		if a.board == nil or a.board == board_name then
			if a.time >= from_t then acts[#acts + 1] = a else before = a end
		end
	end
	if before then table.insert(acts, 1, before) end
	local lines = { string.format("  last %d services (board's view)%s:", #h - first + 1,
		#acts > 0 and ", with the test's actions (>>; * the first service after one)" or "") }
	local ai, pending = 1, nil
	for i = first, #h + 1 do
		local row = h[i]
		-- A service at the moment of an action came before it (the action
		-- is taken between runs of the clock).
		while acts[ai] and (not row or acts[ai].time >= (i == first and -math.huge or h[i - 1].time)
			and acts[ai].time < row.time) do
			local a = acts[ai]
			lines[#lines + 1] = string.format("    %10.4f >> %s%s", a.time, a.text,
				row and "" or period_us and string.format("  (no service of this board since: the next within "
					.. "its period, %g ms)", period_us / 1e3) or "  (no service of this board since)")
			if a.time >= from_t then pending = pending or a end
			ai = ai + 1
		end
		if not row then break end
		local names = {}
		for k in pairs(row.io) do names[#names + 1] = k end
		table.sort(names)
		local parts = {}
		for _, k in ipairs(names) do parts[#parts + 1] = k .. "=" .. fmt_value(row.io[k]) end
		local mark = ""
		if pending then
			mark = string.format("  (* %.1f ms after %s)", (row.time - pending.time) * 1e3, pending.text)
		end
		lines[#lines + 1] = string.format("    %10.4f %s %s%s", row.time, pending and "* " or "  ",
			table.concat(parts, " "), mark)
		pending = nil
	end
	return lines
end

-- What a person needs to see when a test fails: the recent services of
-- each board with the test's actions among them, and the recent events.
function M.details(current, history)
	local lines = {}
	local w = current.world
	if not w then return lines end
	lines[#lines + 1] = string.format("virtual time %.6f s (tick %d)", w:now(), math.floor(w:now() / w:slot() + 0.5))
	for _, b in ipairs(current.boards) do
		local d = w:device(b.name)
		lines[#lines + 1] = string.format("%s: host says %s%s", b.name, d and d.state or "absent",
			d and d.note ~= "" and (" (" .. d.note .. ")") or "")
		if d and next(d.vars) then
			local names = {}
			for k in pairs(d.vars) do names[#names + 1] = k end
			table.sort(names)
			-- A variable declared update = "timer:N" is the copy of its last
			-- publication, up to N s old: say so, and how old it is.
			local timers = w:timers(b.name)
			local parts = {}
			for _, k in ipairs(names) do
				local tv, note = timers[k], ""
				if tv then
					note = string.format(" (timer %g s: %s)", tv.every_s, tv.published_s and string.format(
						"published %.2f s ago", w:now() - tv.published_s) or "not published yet")
				end
				parts[#parts + 1] = k .. "=" .. fmt_value(d.vars[k]) .. note
			end
			lines[#lines + 1] = "  variables: " .. table.concat(parts, " ")
		end
		for _, l in ipairs(services_and_actions(current, history, w:history(b.name), b.name,
			d and d.period_us > 0 and d.period_us or nil)) do lines[#lines + 1] = l end
	end
	local ev = w:events(1)
	if #ev > 0 then
		lines[#lines + 1] = "last events:"
		for i = math.max(1, #ev - 7), #ev do
			lines[#lines + 1] = string.format("  %10.4f %-14s %s", ev[i].time, ev[i].kind, ev[i].text)
		end
	end
	return lines
end

function M.human_duration(s)
	if s >= 3600 then return string.format("%dh%02dm", math.floor(s / 3600), math.floor(s % 3600 / 60)) end
	if s >= 60 then return string.format("%dm%02ds", math.floor(s / 60), math.floor(s % 60)) end
	return string.format("%.3gs", s)
end

function M.reporter(tap)
	local self = { n = 0, failed = 0, virtual = 0, wall = 0 }
	local last_file
	function self.report(r)
		self.n = self.n + 1
		if r.failure then self.failed = self.failed + 1 end
		self.virtual, self.wall = self.virtual + (r.virtual or 0), self.wall + (r.wall or 0)
		local where_ = r.failure and (r.failure.where or r.where) or nil
		if tap then
			print(string.format("%s %d - %s: %s", r.failure and "not ok" or "ok", self.n, r.file, r.name))
			if r.failure then
				print("  ---")
				print("  message: " .. string.format("%q", r.failure.message):gsub("\\\n", "\\n"))
				if where_ then print("  at: " .. where_) end
				for _, l in ipairs(r.details or {}) do print("  # " .. l) end
				print("  ...")
			end
			return
		end
		if r.file ~= last_file then
			print(r.file)
			last_file = r.file
		end
		if not r.failure then
			print(string.format("  ok    %s  (%s virtual, %.2f s wall)", r.name, M.human_duration(r.virtual), r.wall))
			return
		end
		print(string.format("  FAIL  %s", r.name))
		if where_ then print("        at " .. where_) end
		for l in (r.failure.message .. "\n"):gmatch("([^\n]*)\n") do print("        " .. l) end
		for _, l in ipairs(r.failure.frames or {}) do print("        from " .. l) end
		for _, l in ipairs(r.details or {}) do print("        " .. l) end
	end
	return self
end

local function xml(s)
	return (tostring(s):gsub("[&<>\"]", { ["&"] = "&amp;", ["<"] = "&lt;", [">"] = "&gt;", ['"'] = "&quot;" })
		:gsub("[%z\1-\8\11\12\14-\31]", "?"))
end

-- The results as JUnit XML to the open file f, which it closes.
function M.junit(f, results, n, failed)
	local by_file, order = {}, {}
	for _, r in ipairs(results) do
		if not by_file[r.file] then by_file[r.file] = {}; order[#order + 1] = r.file end
		table.insert(by_file[r.file], r)
	end
	f:write('<?xml version="1.0" encoding="UTF-8"?>\n')
	f:write(string.format('<testsuites name="vmac test" tests="%d" failures="%d">\n', n, failed))
	for _, file in ipairs(order) do
		local rs, nf, wall = by_file[file], 0, 0
		for _, r in ipairs(rs) do
			if r.failure then nf = nf + 1 end
			wall = wall + (r.wall or 0)
		end
		f:write(string.format('  <testsuite name="%s" tests="%d" failures="%d" time="%.3f">\n', xml(file), #rs, nf,
			wall))
		for _, r in ipairs(rs) do
			f:write(string.format('    <testcase classname="%s" name="%s" time="%.3f">', xml(file), xml(r.name),
				r.wall or 0))
			if r.failure then
				f:write(string.format('\n      <failure message="%s">%s</failure>\n    ', xml(r.failure.message),
					xml(table.concat(r.details or {}, "\n"))))
			end
			f:write("</testcase>\n")
		end
		f:write("  </testsuite>\n")
	end
	f:write("</testsuites>\n")
	f:close()
end

return M
