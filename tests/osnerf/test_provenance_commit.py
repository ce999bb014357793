"""A command names the commit of the code it loaded."""


def test_a_command_reads_the_commit_before_it_runs(monkeypatch, capsys):
    """A long run writes its result at the end; the commit it names is read when it starts
    (the code it loaded), not when the checkout may already hold the next commit."""
    import importlib

    from osnerf import git_commit
    from osnerf.cli import main

    module = importlib.import_module("osnerf.commands.scenes")
    real = module.run
    cached_at_start = []

    def run(args):
        cached_at_start.append(git_commit.cache_info().currsize)
        return real(args)

    git_commit.cache_clear()
    monkeypatch.setattr(module, "run", run)
    assert main(["scenes"]) == 0
    assert cached_at_start == [1]
