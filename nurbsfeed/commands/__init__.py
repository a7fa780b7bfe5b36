"""The command line's commands, a module each: convert (and what a batch of files needs: batch,
progress, pool), plan, and the analyses (compare, check, plot); common holds what they share
(the profile options, the errors' exit codes) and stops the stop signals. nurbsfeed.cli groups
the commands into `main`; it and this package are the only code that imports click.
"""
