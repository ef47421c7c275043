return { name = "a_name_that_is_far_too_long_to_be_a_driver_name_at_all", version = string.rep("v", 40),
  tick = function() end }
