from stafpipe.cli import app

app()
