"""The reproduction report (`stafpipe plot report`, `stafpipe run reproduce`): every table, figure and claim of the
three papers as a row with the paper's number, ours with its 95 % CI, the criterion, and a computed verdict."""
