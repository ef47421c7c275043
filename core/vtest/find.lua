-- vmac test's test files (core/vtest/runner.lua): every *_test.lua under
-- the folders given, in C order, and the files given by name; those under
-- the working folder named relative to it (docs/TESTING.md).

local function shell_quote(s)
	return "'" .. s:gsub("'", "'\\''") .. "'"
end

local function find_tests(path)
	local p = io.popen("find " .. shell_quote(path) .. " -name '*_test.lua' -type f 2>/dev/null | LC_ALL=C sort")
	local files = {}
	for line in p:lines() do files[#files + 1] = line end
	p:close()
	return files
end

local function is_dir(path)
	local p = io.popen("test -d " .. shell_quote(path) .. " && echo d")
	local r = p:read("*l")
	p:close()
	return r == "d"
end

-- The test files of roots (folders or files), named relative to cwd when
-- under it; or nil and the first root that does not exist.
return function(roots, cwd)
	local files = {}
	for _, p in ipairs(roots) do
		if is_dir(p) then
			for _, f in ipairs(find_tests(p)) do files[#files + 1] = f end
		else
			local f = io.open(p, "r")
			if not f then return nil, p end
			f:close()
			files[#files + 1] = p
		end
	end
	for i, f in ipairs(files) do
		if cwd and f:sub(1, #cwd + 1) == cwd .. "/" then files[i] = f:sub(#cwd + 2) end
	end
	return files
end
