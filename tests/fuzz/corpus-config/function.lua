bus = function() end
